"""Figures of a run, like the report's figures 2-4, as matplotlib Figures.

The caller saves them. Angles and rates are shown in degrees (artifacts keep radians), and ``pD``
as the height ``-pD`` (up positive; artifacts keep NED). Bode phase is drawn in (-360, 0] deg at
the gain crossover, where the -180 deg line and the phase margin are read.

Modules, each importing only :mod:`~quadctl.plots.drawing` (``from quadctl import plots`` gives the
public names of all of them: ``plots.simulation_figures``, ``plots.png_bytes``, ``plots.DPI``, ...):

- :mod:`~quadctl.plots.drawing`: what every figure shares: resolution, colours, a state as drawn, a
  time series thinned to the pixel columns, the PNG bytes, the inputs' limits
- :mod:`~quadctl.plots.simulation`: a simulation's figures (subsystems, inputs, wind, path, tracking error)
- :mod:`~quadctl.plots.frequency`: a broken loop's Bode and Nyquist plots with its margins
- :mod:`~quadctl.plots.sweep`: a sweep's trade-off and a Monte Carlo's percentile bands
- :mod:`~quadctl.plots.schedule`: a gain schedule's envelope and a transition flown with it
"""

from quadctl.plots.drawing import DPI as DPI
from quadctl.plots.drawing import input_limits as input_limits
from quadctl.plots.drawing import pixel_envelope as pixel_envelope
from quadctl.plots.drawing import png_bytes as png_bytes
from quadctl.plots.frequency import margins_figure as margins_figure
from quadctl.plots.frequency import margins_figure_name as margins_figure_name
from quadctl.plots.frequency import phase_about_minus_180 as phase_about_minus_180
from quadctl.plots.schedule import schedule_figure as schedule_figure
from quadctl.plots.schedule import transition_figure as transition_figure
from quadctl.plots.simulation import inputs_figure as inputs_figure
from quadctl.plots.simulation import path_figure as path_figure
from quadctl.plots.simulation import simulation_figure_makers as simulation_figure_makers
from quadctl.plots.simulation import simulation_figures as simulation_figures
from quadctl.plots.simulation import subsystem_figure as subsystem_figure
from quadctl.plots.simulation import tracking_error_figure as tracking_error_figure
from quadctl.plots.simulation import wind_figure as wind_figure
from quadctl.plots.sweep import montecarlo_figure as montecarlo_figure
from quadctl.plots.sweep import sweep_tradeoff_figure as sweep_tradeoff_figure
