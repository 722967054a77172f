"""Text for people: values and hints as messages show them; text made safe per output format."""
