"""The run directory: writing and reading artifacts atomically, with provenance.

Every artifact carries ``quadctl_version``, ``config_hash``, ``config_name``, ``state_names``,
``input_names``; JSON artifacts also a ``created`` timestamp, the only field that differs
between two runs of the same config (NPZ artifacts are byte-identical). JSON is written
with sorted keys and NPZ with fixed zip timestamps, so the same config gives byte-identical
artifacts apart from ``created``.

Modules, each importing only those above it (``from quadctl import artifacts`` gives the public
names of all of them: ``artifacts.write_json``, ``artifacts.read_npz``, ``artifacts.locked``, ...):

- :mod:`~quadctl.artifacts.meta`: the provenance record every artifact carries (:func:`metadata`)
- :mod:`~quadctl.artifacts.json_values`: values as JSON holds them (arrays, complex numbers, infinities)
- :mod:`~quadctl.artifacts.places`: the run directory and its names, kept off symbolic links
- :mod:`~quadctl.artifacts.writing`: atomic writes (tagged temporaries, fsync, rename), cleaning up
- :mod:`~quadctl.artifacts.reading`: reading back with provenance checked; reuse (:func:`is_fresh`)
- :mod:`~quadctl.artifacts.png_stamp`: a figure's config hash in its PNG (:func:`stamp_png`)
- :mod:`~quadctl.artifacts.run_folder`: a run folder's artifacts and the config that made each
  (:func:`run_artifacts`, :class:`MadeBy`)
- :mod:`~quadctl.artifacts.journal`: what a session changes, for the next to finish a killed one
  (:func:`take_over`)
- :mod:`~quadctl.artifacts.lock`: one quadctl per run directory (:func:`locked`; its first holder
  finishes a dead session)
- :mod:`~quadctl.artifacts.session`: one command's writes into a run folder, beside its config, another
  config's run removed, every change undoable (:class:`Session`)
"""

from quadctl.artifacts.journal import take_over as take_over
from quadctl.artifacts.json_values import INFINITY as INFINITY
from quadctl.artifacts.json_values import complex_values as complex_values
from quadctl.artifacts.json_values import decode_floats as decode_floats
from quadctl.artifacts.json_values import jsonable as jsonable
from quadctl.artifacts.lock import LOCK_NAME as LOCK_NAME
from quadctl.artifacts.lock import MARK_NAME as MARK_NAME
from quadctl.artifacts.lock import claim as claim
from quadctl.artifacts.lock import held as held
from quadctl.artifacts.lock import locked as locked
from quadctl.artifacts.meta import FORMAT_VERSION as FORMAT_VERSION
from quadctl.artifacts.meta import metadata as metadata
from quadctl.artifacts.places import ARTIFACT_NAMES as ARTIFACT_NAMES
from quadctl.artifacts.places import PLOTS as PLOTS
from quadctl.artifacts.places import SUBFOLDER_NAMES as SUBFOLDER_NAMES
from quadctl.artifacts.places import SWEEP_PARTS as SWEEP_PARTS
from quadctl.artifacts.places import check_folder as check_folder
from quadctl.artifacts.places import default_out as default_out
from quadctl.artifacts.places import plot_path as plot_path
from quadctl.artifacts.png_stamp import stamp_png as stamp_png
from quadctl.artifacts.reading import NAMES as NAMES
from quadctl.artifacts.reading import SCHEMAS as SCHEMAS
from quadctl.artifacts.reading import InvalidArtifact as InvalidArtifact
from quadctl.artifacts.reading import is_fresh as is_fresh
from quadctl.artifacts.reading import read_json as read_json
from quadctl.artifacts.reading import read_npz as read_npz
from quadctl.artifacts.reading import validate as validate
from quadctl.artifacts.run_folder import MadeBy as MadeBy
from quadctl.artifacts.run_folder import run_artifacts as run_artifacts
from quadctl.artifacts.session import Session as Session
from quadctl.artifacts.session import config_hash_of as config_hash_of
from quadctl.artifacts.writing import STALE_TEMPORARY_AGE as STALE_TEMPORARY_AGE
from quadctl.artifacts.writing import TEMPORARY_TAG as TEMPORARY_TAG
from quadctl.artifacts.writing import json_bytes as json_bytes
from quadctl.artifacts.writing import remove as remove
from quadctl.artifacts.writing import remove_stale_temporaries as remove_stale_temporaries
from quadctl.artifacts.writing import write_bytes as write_bytes
from quadctl.artifacts.writing import write_json as write_json
from quadctl.artifacts.writing import write_npz as write_npz
from quadctl.artifacts.writing import write_together as write_together
