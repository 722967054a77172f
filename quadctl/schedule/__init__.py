"""A gain schedule across the envelope: trims and batched designs at each value, the frozen-point
checks, a reference flown across the schedule."""
