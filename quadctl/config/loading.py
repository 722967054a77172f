"""Finding and loading a config: a file or a bundled name, YAML text or a mapping, validated whole.

Also a value given on the command line for a config key (:func:`check_override`), validated by
that key's own declaration.
"""

from __future__ import annotations

import difflib
import os
import re
from collections.abc import Mapping
from importlib import resources
from pathlib import Path
from typing import Annotated, Any, NamedTuple

from pydantic import ValidationError

from quadctl.config import yamlio
from quadctl.config.checks import check_semantics
from quadctl.config.describe import describe, expected, is_union_tag
from quadctl.config.kinds import misplaced
from quadctl.config.schema import Config
from quadctl.config.schema_paths import section_model
from quadctl.errors import ArgumentTypeError, ConfigError
from quadctl.text.messages import kind_of, show

DEFAULT_CONFIG = "forward"
"""Bundled config used when no ``--config`` is given: the report's forward-flight case."""


class Source(NamedTuple):
    """Where a ``--config`` value led: the file to name in errors, its text, and a note when the
    name could have meant something else (a file here and a bundled config of that name)."""

    label: str
    text: str
    note: str | None = None


def bundled_folder():
    """Where the bundled configs are: the installed package's ``configs`` (a wheel is built with the
    repository's ``configs/`` copied in), else the ``configs/`` folder at the top of the checkout the
    package is imported from (a clone, an editable install)."""
    packaged = resources.files("quadctl") / "configs"
    if packaged.is_dir():
        return packaged
    return Path(__file__).resolve().parent.parent.parent / "configs"


def bundled_names() -> list[str]:
    """Names of the configs that ship with quadctl (without ``.yaml``)."""
    folder = bundled_folder()
    return sorted(p.name[:-5] for p in folder.iterdir() if p.name.endswith(".yaml"))


def bundled(name: str) -> Source:
    """A bundled config by name (``forward``), whatever files the working folder holds."""
    res = bundled_folder() / f"{name}.yaml"
    return Source(f"{name}.yaml", res.read_text(encoding="utf-8"))


def locate(spec: str | Path | None) -> Source:
    """Find a config: a file, else a bundled name (with or without ``.yaml``).

    A folder is never a config. A bundled name resolves unless a file of exactly that name
    exists; when both could be meant (a file ``forward`` or ``forward.yaml`` here and a bundled
    ``forward``), :attr:`Source.note` says which was taken and how to ask for the other.

    Returns
    -------
    Source : (label, text, note)
        The file name to cite in errors, its YAML text, and the note (or None).

    Raises
    ------
    ConfigError
        No such file and no bundled config of that name, a folder of that name and no bundled
        config, or a file that cannot be read (too large, not UTF-8, no permission).
    """
    spec = DEFAULT_CONFIG if spec is None else str(spec)
    if not spec.strip():  # '' is the working folder: it was refused as ": is a folder, not a config file"
        raise ConfigError(f"{spec!r}: an empty config name; give a config file's path or a bundled config's name "
                          "(`quadctl configs` lists them)")
    path = Path(spec)
    name = re.sub(r"\.ya?ml$", "", spec)
    is_name = "/" not in name and os.sep not in name and name in bundled_names()
    # os.path's tests, not Path's: a name too long for the system is no such file, where Path's raise
    if os.path.exists(path) and not os.path.isdir(path):  # a file, a pipe or a device: read (with a size cap)
        note = (f"-c {spec}: using the file {path}, not the bundled config `{name}` "
                f"(`quadctl configs --show {name}` prints that one)") if is_name else None
        return Source(str(path), yamlio.read_text(path, spec, "config file"), note)
    if is_name:
        here = [p for p in (name, f"{name}.yaml", f"{name}.yml") if os.path.isfile(p)]
        note = (f"-c {spec}: using the bundled config `{name}`, not the file {here[0]} in this folder "
                f"(give -c ./{here[0]} for the file)") if here else None
        return bundled(name)._replace(note=note)
    if os.path.isdir(path):
        raise ConfigError(f"{spec}: is a folder, not a config file; give a .yaml file")
    here = "here" if str(path.parent) == "." else f"in {path.parent}"
    near = [f"{f}` (a file {here})" for f in near_files(path)] or [
        f"{b}`" for b in difflib.get_close_matches(name, bundled_names(), n=1) if "/" not in name]
    guess = f"did you mean `{near[0]}? " if near else ""
    raise ConfigError(
        f"{spec}: no such file and no bundled config of that name; {guess}"
        f"bundled: {', '.join(bundled_names())}")


FOLDER_SCAN = 1000
"""Entries of a folder looked at for a config file of a near name (a mistyped ``-c``): a bound for a
folder of many files."""


def near_files(path: Path) -> list[str]:
    """The YAML file in ``path``'s folder whose name is nearest ``path``'s (``f450.yml`` -> ``f450.yaml``),
    as a path to give ``-c``; empty when none is near.

    >>> near_files(Path("no-such-folder/f450.yml"))
    []
    """
    import itertools

    def stem(name: str) -> str:
        return re.sub(r"\.ya?ml$", "", name)

    try:
        entries = list(itertools.islice(os.scandir(path.parent), FOLDER_SCAN))
    except OSError:
        return []
    files = {stem(e.name): e.name for e in entries
             if re.search(r"\.ya?ml$", e.name) and e.name != path.name and e.is_file()}
    near = difflib.get_close_matches(stem(path.name), list(files), n=1)
    return [str(path.parent / files[near[0]])] if near else []


def load(spec: str | Path | None = None) -> Config:
    """Load and validate a config from a path or a bundled name (default: ``forward``).

    Parameters
    ----------
    spec : str or Path, optional
        A YAML file, or the name of a bundled config (``quadctl configs`` lists them); None: ``forward``.

    Returns
    -------
    Config
        Validated, every default filled in.

    Raises
    ------
    ConfigError
        With one line naming the file, key path, value and the fix.
    ArgumentTypeError
        ``spec`` is not a path or a name (a dict: :func:`from_dict` validates a mapping); a ``TypeError``.

    Examples
    --------
    >>> import quadctl as qc
    >>> cfg = qc.load_config("hover")
    >>> cfg.name, cfg.vehicle.mass, list(cfg.lqr)
    ('hover', 0.068, ['altitude', 'roll', 'pitch', 'yaw'])
    """
    if spec is not None and not isinstance(spec, (str, os.PathLike)):
        fix = ("validate a mapping with quadctl.config.from_dict(data)" if isinstance(spec, Mapping)
               else "give a YAML file's path or a bundled config's name (quadctl.config.bundled_names())")
        raise ArgumentTypeError(f"load_config takes a file path or a bundled config's name, got "
                                f"{type(spec).__name__}; {fix}")
    if isinstance(spec, str) and not spec.strip():  # '' resolved to the working folder: ': is a folder'
        raise ConfigError(f"load_config: the config's name is empty ({spec!r}); give a YAML file's path or a bundled "
                          "config's name (quadctl.config.bundled_names())")
    source = locate(spec)
    return parse(source.text, source.label)


def parse(text: str, label: str = "<config>") -> Config:
    """Validate YAML text as a config; ``label`` names it in errors (see :mod:`quadctl.config.yamlio`)."""
    return from_dict(yamlio.load(text, label, ConfigError), label)


def from_dict(data: Any, label: str = "<config>") -> Config:
    """Validate a mapping (as YAML gives it) as a config."""
    if not isinstance(data, dict):
        raise ConfigError(f"{label}: the config is {kind_of(data)}, not a mapping of keys; "
                          "start from `quadctl configs --show forward`")
    try:
        cfg = Config.model_validate(data)
    except ValidationError as exc:

        raise ConfigError(misplaced(data, label, "config") or describe(exc, data, label)) from None
    check_semantics(cfg, label)
    return cfg


OVERRIDES = {"--rate": "controller.rate"}
"""Command-line options that stand for a config key: each takes the key's own declaration (its type,
bounds, unit and messages) through :func:`check_override`."""


def key_field(key: str):
    """The schema's declaration (pydantic ``FieldInfo``) of a config key path (``controller.rate``)."""
    *parents, leaf = key.split(".")
    model = section_model(parents)
    if model is None or leaf not in model.model_fields:
        raise KeyError(f"{key}: not a config key")
    return model.model_fields[leaf]


def check_override(option: str, value: Any, key: str | None = None) -> Any:
    """Validate ``value``, given on the command line as ``option``, against the config key it
    overrides (:data:`OVERRIDES`, or ``key``): the same bounds and words as that key in a file.

    Returns
    -------
    The value as the key holds it.

    Raises
    ------
    ConfigError
        ``--rate = inf: must be a finite number (not NaN or infinity); --rate is controller.rate``:
        one line naming the option, the value, what is allowed and the key.

    Examples
    --------
    >>> check_override("--rate", 200.0)
    200.0
    >>> try:
    ...     check_override("--rate", 1e12)
    ... except ConfigError as exc:
    ...     print(str(exc)[:48])
    --rate = 1000000000000: must be at most 100000 (
    """
    key = key or OVERRIDES[option]
    try:
        return _validated(key, value)
    except ValidationError as exc:
        raise ConfigError(f"{option} = {show(value)}: {_expected_of(exc, key)}; {option} is {key}") from None


def refusal(key: str, value: Any) -> str | None:
    """What the declaration of the config key ``key`` (``simulation.duration``) says ``value`` must be
    when it refuses the value on its own, whatever the rest of the config holds; None when it takes it,
    or when ``key`` is not one declared key (an index: ``vehicle.inertia[0]``).

    Examples
    --------
    >>> refusal("simulation.duration", -1)
    'must be greater than 0.0 (s)'
    >>> refusal("simulation.duration", 4.0) is None
    True
    """
    try:
        _validated(key, value)
    except KeyError:
        return None
    except ValidationError as exc:
        return _expected_of(exc, key)
    return None


def _validated(key: str, value: Any) -> Any:
    """``value`` as the declaration of the config key ``key`` takes it (pydantic's ValidationError if not;
    KeyError if ``key`` is not one declared key)."""
    from pydantic import TypeAdapter

    field = key_field(key)
    kind = Annotated[(field.annotation, *field.metadata)] if field.metadata else field.annotation
    return TypeAdapter(kind).validate_python(value)


def _expected_of(exc: ValidationError, key: str) -> str:
    """What the key ``key`` takes, from the first error of its validation."""
    err = exc.errors()[0]
    return expected(err, key.split(".") + [p for p in err["loc"] if not is_union_tag(p)])
