"""The YAML config: schema, validation, loading and the bundled configs.

A config is validated whole on load: unknown keys are refused (with the nearest valid
key suggested), numbers must be finite, names must exist, and every error is one
:class:`~quadctl.errors.ConfigError` line naming the file, the key path, the value
and what is allowed.

Modules, each importing only those above it (``from quadctl import config`` gives every public
name of all of them: ``config.load``, ``config.Config``, ``config.check_weight``, ``config.MAX_DURATION``):

- :mod:`~quadctl.config.schema_types`: the sections' base and the strict number types of their fields
- :mod:`~quadctl.config.vehicle_schema`: the vehicle's sections (``vehicle:``, ``motors:``, ``limits:``)
- :mod:`~quadctl.config.simulation_schema`: the ``simulation:`` section (noise, wind, plant, reference)
- :mod:`~quadctl.config.controller_schema`: the sections of what runs on the flight computer (``controller:``,
  ``estimator:``)
- :mod:`~quadctl.config.schema`: :class:`Config` and the design's sections (frozen pydantic models, limits and units)
- :mod:`~quadctl.config.schema_paths`: the schema walked by a key path; the value a config leaves out
- :mod:`~quadctl.config.weights`: the rules an LQR weight (Q or R) obeys, for one weight or many
- :mod:`~quadctl.config.describe`: a pydantic ``ValidationError`` as the one line a user reads
- :mod:`~quadctl.config.vehicle_checks`: a vehicle that can exist: its inertia and its rotors
- :mod:`~quadctl.config.unit_limits`: the bounds of values by unit: the longest run, the largest initial
  offset, one limit per unit for every position, velocity, heading and time
- :mod:`~quadctl.config.key_units`: the unit of the value at a key path (a sweep's parameter columns)
- :mod:`~quadctl.config.checks`: the checks after the schema: rules across fields, bounds in context
- :mod:`~quadctl.config.render`: the schema shown to people and editors (``quadctl configs --show``)
- :mod:`~quadctl.config.kinds`: what a file that fails is instead (a sweep file, an artifact)
- :mod:`~quadctl.config.loading`: finding, loading and validating a config; a command-line value checked
"""

from quadctl.config.checks import DELAY_SAMPLES_TOL as DELAY_SAMPLES_TOL
from quadctl.config.controller_schema import MAX_DELAY_SAMPLES as MAX_DELAY_SAMPLES
from quadctl.config.controller_schema import MAX_RATE as MAX_RATE
from quadctl.config.controller_schema import ControllerConfig as ControllerConfig
from quadctl.config.controller_schema import DelaySamples as DelaySamples
from quadctl.config.controller_schema import EstimatorConfig as EstimatorConfig
from quadctl.config.controller_schema import FiltersConfig as FiltersConfig
from quadctl.config.controller_schema import PidConfig as PidConfig
from quadctl.config.key_units import key_unit as key_unit
from quadctl.config.loading import DEFAULT_CONFIG as DEFAULT_CONFIG
from quadctl.config.loading import FOLDER_SCAN as FOLDER_SCAN
from quadctl.config.loading import OVERRIDES as OVERRIDES
from quadctl.config.loading import Source as Source
from quadctl.config.loading import bundled as bundled
from quadctl.config.loading import bundled_names as bundled_names
from quadctl.config.loading import check_override as check_override
from quadctl.config.loading import from_dict as from_dict
from quadctl.config.loading import key_field as key_field
from quadctl.config.loading import load as load
from quadctl.config.loading import locate as locate
from quadctl.config.loading import near_files as near_files
from quadctl.config.loading import parse as parse
from quadctl.config.loading import refusal as refusal
from quadctl.config.render import SCHEMA_DIALECT as SCHEMA_DIALECT
from quadctl.config.render import TOP_LEVEL_ABSENT as TOP_LEVEL_ABSENT
from quadctl.config.render import json_schema as json_schema
from quadctl.config.render import shown_yaml as shown_yaml
from quadctl.config.schema import LATER_KEYS as LATER_KEYS
from quadctl.config.schema import MAX_NAME_LENGTH as MAX_NAME_LENGTH
from quadctl.config.schema import MAX_SCHEDULE_POINTS as MAX_SCHEDULE_POINTS
from quadctl.config.schema import NAME_PATTERN as NAME_PATTERN
from quadctl.config.schema import NAME_RULE as NAME_RULE
from quadctl.config.schema import SUBSYSTEM_NAME_PATTERN as SUBSYSTEM_NAME_PATTERN
from quadctl.config.schema import Config as Config
from quadctl.config.schema import LqrWeights as LqrWeights
from quadctl.config.schema import ScheduleConfig as ScheduleConfig
from quadctl.config.schema import StartedFrom as StartedFrom
from quadctl.config.schema import SubsystemConfig as SubsystemConfig
from quadctl.config.schema import TrimConfig as TrimConfig
from quadctl.config.schema_paths import PLANT as PLANT
from quadctl.config.schema_paths import default_at as default_at
from quadctl.config.schema_paths import first_model as first_model
from quadctl.config.schema_paths import section_model as section_model
from quadctl.config.schema_types import MAX_NOISE as MAX_NOISE
from quadctl.config.schema_types import Matrix as Matrix
from quadctl.config.schema_types import NonNegative as NonNegative
from quadctl.config.schema_types import Number as Number
from quadctl.config.schema_types import Positive as Positive
from quadctl.config.schema_types import Vector3 as Vector3
from quadctl.config.simulation_schema import MAX_GUSTS as MAX_GUSTS
from quadctl.config.simulation_schema import MAX_TURBULENCE_SIGMA as MAX_TURBULENCE_SIGMA
from quadctl.config.simulation_schema import MAX_WIND as MAX_WIND
from quadctl.config.simulation_schema import MAX_WIND_ALTITUDE as MAX_WIND_ALTITUDE
from quadctl.config.simulation_schema import TURBULENCE_LENGTH as TURBULENCE_LENGTH
from quadctl.config.simulation_schema import GustConfig as GustConfig
from quadctl.config.simulation_schema import NoiseConfig as NoiseConfig
from quadctl.config.simulation_schema import PlantConfig as PlantConfig
from quadctl.config.simulation_schema import ReferenceConfig as ReferenceConfig
from quadctl.config.simulation_schema import SetpointConfig as SetpointConfig
from quadctl.config.simulation_schema import SimulationConfig as SimulationConfig
from quadctl.config.simulation_schema import TurbulenceConfig as TurbulenceConfig
from quadctl.config.simulation_schema import WaypointConfig as WaypointConfig
from quadctl.config.simulation_schema import WindComponent as WindComponent
from quadctl.config.simulation_schema import WindConfig as WindConfig
from quadctl.config.simulation_schema import WindVector as WindVector
from quadctl.config.unit_limits import MAX_DURATION as MAX_DURATION
from quadctl.config.unit_limits import MAX_DURATION_ENV as MAX_DURATION_ENV
from quadctl.config.unit_limits import MAX_OFFSET as MAX_OFFSET
from quadctl.config.unit_limits import MAX_TILT_OFFSET as MAX_TILT_OFFSET
from quadctl.config.unit_limits import UNIT_KEYS as UNIT_KEYS
from quadctl.config.unit_limits import UNIT_LIMITS as UNIT_LIMITS
from quadctl.config.unit_limits import max_duration_s as max_duration_s
from quadctl.config.vehicle_checks import INERTIA_TRIANGLE_RTOL as INERTIA_TRIANGLE_RTOL
from quadctl.config.vehicle_schema import INERTIA_DESCRIPTION as INERTIA_DESCRIPTION
from quadctl.config.vehicle_schema import MASS_RANGE as MASS_RANGE
from quadctl.config.vehicle_schema import MAX_DRAG as MAX_DRAG
from quadctl.config.vehicle_schema import MAX_GRAVITY as MAX_GRAVITY
from quadctl.config.vehicle_schema import MAX_ROTOR_TIME_CONSTANT as MAX_ROTOR_TIME_CONSTANT
from quadctl.config.vehicle_schema import Drag as Drag
from quadctl.config.vehicle_schema import Gravity as Gravity
from quadctl.config.vehicle_schema import InputLimits as InputLimits
from quadctl.config.vehicle_schema import Mass as Mass
from quadctl.config.vehicle_schema import MotorsConfig as MotorsConfig
from quadctl.config.vehicle_schema import RotorTimeConstant as RotorTimeConstant
from quadctl.config.vehicle_schema import VehicleConfig as VehicleConfig
from quadctl.config.vehicle_schema import inertia_parts as inertia_parts
from quadctl.config.weights import DEFINITENESS_RTOL as DEFINITENESS_RTOL
from quadctl.config.weights import SYMMETRY_RTOL as SYMMETRY_RTOL
from quadctl.config.weights import WEIGHT_RANGE as WEIGHT_RANGE
from quadctl.config.weights import check_weight as check_weight
from quadctl.config.weights import diagonal_weights_pass as diagonal_weights_pass
from quadctl.config.weights import weight_matrix as weight_matrix
