"""The vehicle's physics: the CasADi model (the only place the equations of motion live), rotors and
mixing, wind, noise, a reference's path and its differential-flatness feedforward."""
