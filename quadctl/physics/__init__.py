"""The vehicle's physics: the CasADi model (the only place the equations of motion live), rotors and
mixing, wind, noise, a reference's path, its differential-flatness feedforward and the rows the loop
reads them from."""
