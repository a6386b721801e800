"""A batch: typed jobs read from a batch file (YAML) or from script paths and globs.

A batch file (docs/batch.md has the full format)::

    name: ci
    defaults: {timeout_s: 600, retries: 1, expect: {max_wall_time_s: 300}}
    jobs:
      - run: smoke.xml                       # a shipped script or a path relative to this file
        options: {seed: 0}
        expect: {min_coverage_pct: 30, max_std_mm: 0.5}
      - autoscan: {n: 4, resolution: 0.2, pictures: false}
        matrix: {object: [bottle, mug], seed: [0, 1]}
        exclude: [{object: mug, seed: 1}]
        expect: {min_coverage_pct: 60}

Each job is one ``recon <command>`` process; a ``matrix`` expands a job into one job per
combination of its values (a key that is an option of the command sets that option; every
key can be used as ``{key}`` in the name, the script path and string option values).
Options are checked against the command's own options (names, types), so a typo fails when
the batch is read, as ``file:line key: what is wrong``. The commands are the command line's:
``recon batch`` hands them in as :class:`Commands` (this package does not read the command
line, which sits above it).

One module on purpose (about 540 lines): the batch file grammar (keys, matrix expansion,
substitution, pass criteria) is read in one place so that every error names file:key the
same way.
"""

from __future__ import annotations

import dataclasses
import glob
import itertools
import math
import re
import sys
from collections.abc import Collection, Mapping
from dataclasses import dataclass, field
from enum import StrEnum
from pathlib import Path
from typing import Protocol

from recon_cli.errors import FileError, InputError
from recon_cli.inputs.numbers import described
from recon_cli.inputs.schema import check as check_schema
from recon_cli.inputs.yamlfile import Map, read_yaml, shown_key
from recon_cli.paths import BATCHES_DIR, SCRIPTS_DIR

MAX_JOBS = 10_000
DEFAULT_TIMEOUT_S = 3600.0  # [s] per job attempt
DEFAULT_RETRIES = 1  # extra attempts after an infrastructure failure
#: the module a job's process runs (``python -m recon_cli <command> ...``)
ENTRY_MODULE = "recon_cli"


class JobKind(StrEnum):
    """The recon command a job runs."""

    RUN = "run"  # recon run SCRIPT
    VALIDATE = "validate"  # recon validate SCRIPT (no output folder: a cheap job)
    AUTOSCAN = "autoscan"
    CAPTURE = "capture"

    @property
    def takes_script(self) -> bool:
        return self in (JobKind.RUN, JobKind.VALIDATE)

    @property
    def writes_out(self) -> bool:
        return self is not JobKind.VALIDATE


#: expectation key -> (the measured value it bounds, unit, the bound is a minimum)
METRICS = {
    "min_coverage_pct": ("coverage", "%", True),
    "max_std_mm": ("std", "mm", False),
    "max_pose_error_mm": ("pose_error", "mm", False),
    "max_planning_failures": ("planning_failures", "", False),
    "max_wall_time_s": ("wall_time", "s", False),
}
LABELS = {"coverage": "coverage", "std": "std", "pose_error": "pose error", "planning_failures": "planning failures",
          "wall_time": "wall time"}

#: which metrics each kind of job can measure (from its reports; docs/batch.md)
MEASURES = {
    JobKind.RUN: frozenset(METRICS),
    JobKind.AUTOSCAN: frozenset(METRICS),
    JobKind.CAPTURE: frozenset({"max_planning_failures", "max_wall_time_s"}),
    JobKind.VALIDATE: frozenset({"max_wall_time_s"}),
}

#: options a batch sets itself or that make no sense in a batch
RESERVED = {"out": "the batch gives every job its own output folder",
            "append": "every job writes into a new folder",
            "station": "a batch runs in the simulation (jobs run in parallel; a station has one robot)",
            "help": "not an option of a job"}


@dataclass(frozen=True)
class Expectations:
    """Pass criteria of a job; None: not checked. Coverage of the reference surface [%]
    (1 mm tolerance), std of the fused cloud's signed distances [mm], mean camera pose
    error of the registration against the simulation's truth [mm], planning failures,
    wall time of the job [s]."""

    min_coverage_pct: float | None = None
    max_std_mm: float | None = None
    max_pose_error_mm: float | None = None
    max_planning_failures: int | None = None
    max_wall_time_s: float | None = None

    def merged(self, over: Expectations) -> Expectations:
        """These expectations with every bound ``over`` sets replaced."""
        return dataclasses.replace(self, **{k: v for k, v in dataclasses.asdict(over).items() if v is not None})

    def only(self, keys: Collection[str]) -> Expectations:
        """These expectations without the bounds whose names are not in ``keys``."""
        return dataclasses.replace(self, **{k: None for k in dataclasses.asdict(self) if k not in keys})

    def items(self) -> list[tuple[str, float]]:
        return [(k, v) for k, v in dataclasses.asdict(self).items() if v is not None]

    def to_dict(self) -> dict:
        return dict(self.items())


@dataclass(frozen=True)
class JobSpec:
    """One isolated ``recon`` process of a batch."""

    name: str  # unique in the batch; also the name of the job's folder
    kind: JobKind
    args: tuple[str, ...]  # after "recon <kind>", without --out
    cwd: Path  # relative paths in args are relative to it (the batch file's folder)
    timeout_s: float  # [s] per attempt
    retries: int  # extra attempts after an infrastructure failure
    expect: Expectations = Expectations()
    env: tuple[tuple[str, str], ...] = ()
    source: str = ""  # file:line of the job entry
    views: int | None = None  # capture: how many views it should scan
    matrix: tuple[tuple[str, str], ...] = ()  # the matrix values of this job

    def command(self, out: Path | None) -> list[str]:
        """The argv of one attempt (``out``: the job's recon output folder)."""
        argv = [sys.executable, "-m", ENTRY_MODULE, self.kind.value, *self.args]
        if self.kind.writes_out and out is not None:
            argv += ["--out", str(out)]
        return argv

    def fingerprint(self) -> dict:
        """What makes two runs of a job the same run (for --resume)."""
        return {"kind": self.kind.value, "args": list(self.args), "cwd": str(self.cwd), "env": dict(self.env)}

    def to_dict(self) -> dict:
        return {"name": self.name, "kind": self.kind.value, "args": list(self.args), "cwd": str(self.cwd),
                "timeout_s": self.timeout_s, "retries": self.retries, "expect": self.expect.to_dict(),
                "env": dict(self.env), "source": self.source, "matrix": dict(self.matrix)}


@dataclass(frozen=True)
class BatchSpec:
    name: str
    jobs: tuple[JobSpec, ...]
    sources: tuple[str, ...] = field(default=())


@dataclass(frozen=True)
class Overrides:
    """Command-line settings: they replace a batch file's defaults (a job's own values win)."""

    timeout_s: float | None = None
    retries: int | None = None
    record: bool = False  # every job whose command can, writes a 3D recording (--record)


# ----------------------------------------------------------------------------- the options of a command
@dataclass(frozen=True)
class CommandOption:
    """An option of a recon command, as a batch file names it."""

    key: str  # the long option without dashes, '-' as '_' (resolution, pictures)
    flag: str  # --resolution
    off: str | None  # --no-pictures of a --pictures/--no-pictures pair
    is_flag: bool


class Commands(Protocol):
    """The recon commands that jobs run, as the command line defines them (``recon batch``
    gives them; a batch checks every job's options against them before anything runs)."""

    def options(self, kind: JobKind) -> Mapping[str, CommandOption]:
        """The options of ``recon <kind>`` by their batch-file key."""
        ...

    def check(self, kind: JobKind, args: tuple[str, ...]) -> str | None:
        """The command's own message when it would refuse ``recon <kind> ARGS`` (parsed, not
        run), else None."""
        ...


def _option_args(kind: JobKind, options: dict, where: dict, commands: Commands) -> tuple[str, ...]:
    """``--flag value`` arguments of ``options`` for ``recon <kind>``, each checked by the
    command's own parser (``where[key]``: the location of the key, for the message)."""
    known = commands.options(kind)
    args: list[str] = []
    for key, value in options.items():
        w = where[key]
        name = shown_key(key) or "<key>"  # (a key that is not a plain name is not repeated)
        if key in RESERVED:
            raise InputError(f"{w}: option '{key}' cannot be set in a batch", hint=RESERVED[key])
        opt = known.get(key)
        if opt is None:
            raise InputError(f"{w}: recon {kind.value} has no option '{name}'",
                             hint="choose one of: " + ", ".join(k for k in known if k not in RESERVED))
        if opt.is_flag:
            if not isinstance(value, bool):
                raise InputError(f"{w}: '{name}' is a switch; write true or false")
            piece = [opt.flag] if value else ([opt.off] if opt.off else [])
        elif isinstance(value, dict | list) or value is None:
            raise InputError(f"{w}: '{name}' needs one value, not {described(value)}")
        else:
            piece = [opt.flag, _format_number(value)]
        problem = commands.check(kind, ("SCRIPT.xml",) * kind.takes_script + tuple(piece))
        if problem:  # the parser's words, without the value it quotes
            raise InputError(f"{w}: {problem.replace(piece[-1], '<value>') if len(piece) > 1 else problem}")
        args += piece
    return tuple(args)


def _format_number(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    return str(value)


# ----------------------------------------------------------------------------- reading
_PLACEHOLDER = re.compile(r"\{(\w+)\}")
_JOB_KEYS = ("name", *(k.value for k in JobKind), "options", "matrix", "exclude", "expect", "timeout_s",
             "retries", "env")
_DEFAULT_KEYS = ("timeout_s", "retries", "expect", "env", "options")
_TOP_KEYS = ("name", "defaults", "jobs")
_NAME_CHARS = re.compile(r"[^A-Za-z0-9_.=+-]+")


@dataclass(frozen=True)
class Loc:
    """Where a value is in a batch file: ``file:line key.path``."""

    path: Path
    line: int | None = None
    keys: str = ""

    def at(self, mapping, key) -> Loc:
        """The location of ``mapping[key]`` (a mapping read by :func:`load_yaml`)."""
        lines = getattr(mapping, "lines", None)
        line = lines.get(key) if isinstance(lines, dict) else None
        name = shown_key(key) or "<key>"  # a key that is not a plain name is not repeated
        return Loc(self.path, line or self.line, f"{self.keys}.{name}" if self.keys else name)

    def item(self, seq, i: int) -> Loc:
        lines = getattr(seq, "lines", None)
        line = lines[i] if isinstance(lines, list) and i < len(lines) else None
        return Loc(self.path, line or self.line, f"{self.keys}[{i}]")

    def __str__(self) -> str:
        where = f"{self.path}:{self.line}" if self.line else str(self.path)
        return f"{where} {self.keys}" if self.keys else where


def _known_keys(mapping, keys, loc: Loc) -> None:
    for k in mapping:
        if k not in keys:
            raise InputError(f"{loc.at(mapping, k)}: unknown key", hint="known keys: " + ", ".join(keys))


def _mapping(value, loc: Loc, what: str) -> dict:
    if value is None:
        return Map()
    if not isinstance(value, dict):
        raise InputError(f"{loc}: {what} must be a mapping (key: value), not {type(value).__name__}")
    return value


def _check_number(value, loc: Loc, *, integer: bool, positive: bool) -> None:
    ok = isinstance(value, int | float) and not isinstance(value, bool) and value == value
    if ok and integer and not float(value).is_integer():
        ok = False
    if not ok or value < 0 or (positive and value == 0) or value == float("inf"):
        kind = "a whole number" if integer else "a number"
        shown = f"{value:g}" if isinstance(value, int | float) and not isinstance(value, bool) else described(value)
        raise InputError(f"{loc}: {shown} is not {kind} {'> 0' if positive else '>= 0'}")


def _number(value, loc: Loc, *, positive: bool = False) -> float:
    _check_number(value, loc, integer=False, positive=positive)
    return float(value)


def _whole(value, loc: Loc) -> int:
    _check_number(value, loc, integer=True, positive=False)
    return int(value)


def _expectations(value, loc: Loc, kind: JobKind | None) -> Expectations:
    m = _mapping(value, loc, "expect")
    _known_keys(m, tuple(METRICS), loc)
    bounds: dict[str, float] = {}
    failures: int | None = None
    for key, bound in m.items():
        if kind is not None and key not in MEASURES[kind]:
            raise InputError(f"{loc.at(m, key)}: a {kind.value} job does not measure this",
                             hint=f"a {kind.value} job can expect: {', '.join(sorted(MEASURES[kind]))}")
        if key == "max_planning_failures":
            failures = _whole(bound, loc.at(m, key))
        else:
            bounds[key] = _number(bound, loc.at(m, key))
    return Expectations(min_coverage_pct=bounds.get("min_coverage_pct"), max_std_mm=bounds.get("max_std_mm"),
                        max_pose_error_mm=bounds.get("max_pose_error_mm"), max_planning_failures=failures,
                        max_wall_time_s=bounds.get("max_wall_time_s"))


@dataclass(frozen=True)
class _Defaults:
    """A batch file's ``defaults:`` (None: not set there)."""

    expect: Expectations = Expectations()
    env: tuple[tuple[str, str], ...] = ()
    options: dict = field(default_factory=dict)
    timeout_s: float | None = None
    retries: int | None = None


#: environment variables a job may not set: they choose which code the interpreter, the
#: dynamic loader or a library loads and runs (a batch file would run code from anywhere)
FORBIDDEN_ENV = ("PATH", "GCONV_PATH", "LOCPATH", "NLSPATH", "HOSTALIASES", "RESOLV_HOST_CONF", "OPENSSL_CONF",
                 "OPENSSL_ENGINES", "BASH_ENV", "ENV", "IFS", "SHELLOPTS", "RECON_HOME", "MUJOCO_PLUGIN_DIR",
                 "GENICAM_GENTL64_PATH", "GENICAM_GENTL32_PATH", "TCL_LIBRARY", "MPLCONFIGDIR", "MPLBACKEND")
#: ... and every name with one of these prefixes
FORBIDDEN_ENV_PREFIXES = ("PYTHON", "LD_", "DYLD_", "MALLOC_", "GLIBC_", "__EGL", "__GL", "LIBGL_", "MESA_",
                          "GALLIUM_", "VK_", "PYDEVD", "COV_CORE", "DASK_")


def env_refusal(name: str) -> str | None:
    """Why a job may not set the environment variable ``name`` (None: it may)."""
    upper = name.upper()
    if upper in FORBIDDEN_ENV or upper.startswith(FORBIDDEN_ENV_PREFIXES):
        return ("it chooses which code the interpreter, the loader or a library runs; set it for the whole "
                "batch in the shell that starts recon batch, if at all")
    return None


def _env(value, loc: Loc) -> tuple[tuple[str, str], ...]:
    m = _mapping(value, loc, "env")
    out = []
    for k, v in m.items():
        if not isinstance(k, str) or not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", k) or isinstance(v, dict | list):
            raise InputError(f"{loc.at(m, k)}: not an environment variable (NAME: value)")
        why = env_refusal(k)
        if why:
            raise InputError(f"{loc.at(m, k)}: a job may not set {k}", hint=why)
        text = _format_number(v)
        if "\0" in text:
            raise InputError(f"{loc.at(m, k)}: the value holds a NUL character")
        out.append((k, text))
    return tuple(out)


def _substitute(text: str, values: dict[str, str], loc: Loc) -> str:
    def repl(m: re.Match) -> str:
        if m.group(1) not in values:
            raise InputError(f"{loc}: {{{shown_key(m.group(1)) or '<key>'}}} is not a matrix key",
                             hint="matrix keys: " + (", ".join(values) or "none (the job has no matrix)"))
        return values[m.group(1)]

    return _PLACEHOLDER.sub(repl, text)


def _resolve_script(text: str, base: Path, loc: Loc) -> Path:
    p = Path(text).expanduser()
    candidates = [p] if p.is_absolute() else [base / p, SCRIPTS_DIR / p]
    if not p.is_absolute() and len(p.parts) > 1 and p.parts[0] == SCRIPTS_DIR.name:
        candidates.append(SCRIPTS_DIR.joinpath(*p.parts[1:]))
    for c in candidates:
        if c.is_file():
            return c.resolve()
    raise FileError(f"{loc}: script {text} not found",
                    hint="looked in " + ", ".join(dict.fromkeys(str(c.parent) for c in candidates)))


def _job_name(value: str, loc: Loc | str) -> str:
    name = _NAME_CHARS.sub("_", value).strip("._")
    if not name:
        raise InputError(f"{loc}: the job name has no letters or digits")
    return name[:120]


def _uses(text, key: str) -> bool:
    return isinstance(text, str) and f"{{{key}}}" in text


def _expand(path: Path, entry: dict, loc: Loc, defaults: _Defaults, overrides: Overrides,
            commands: Commands) -> list[JobSpec]:
    """The jobs of one entry of ``jobs:`` (one per matrix combination)."""
    base = path.parent.resolve()
    _known_keys(entry, _JOB_KEYS, loc)
    kinds = [k for k in JobKind if k.value in entry]
    if len(kinds) != 1:
        raise InputError(f"{loc}: a job names exactly one command, found "
                         f"{', '.join(k.value for k in kinds) or 'none'}",
                         hint="write one of: run: SCRIPT, validate: SCRIPT, autoscan: {...}, capture: {...}")
    kind = kinds[0]
    raw = entry[kind.value]
    if kind.takes_script:
        if not isinstance(raw, str) or not raw.strip():
            raise InputError(f"{loc.at(entry, kind.value)}: needs a script path, e.g. {kind.value}: smoke.xml")
        options = _mapping(entry.get("options"), loc.at(entry, "options"), "options")
        opt_loc = loc.at(entry, "options")
        if kind is JobKind.VALIDATE and options:
            raise InputError(f"{opt_loc}: recon validate has no options")
    else:
        if "options" in entry:
            raise InputError(f"{loc.at(entry, 'options')}: the options of an {kind.value} job go under "
                             f"'{kind.value}:'", hint=f"e.g. {kind.value}: {{resolution: 0.2, seed: 1}}")
        opt_loc = loc.at(entry, kind.value)
        options = _mapping(raw, opt_loc, f"{kind.value} options")

    # the matrix: one job per combination, minus the excluded ones
    mat_loc = loc.at(entry, "matrix")
    matrix = _mapping(entry.get("matrix"), mat_loc, "matrix")
    command_keys = commands.options(kind)
    for key, values in matrix.items():
        if not isinstance(values, list) or not values:
            raise InputError(f"{mat_loc.at(matrix, key)}: a matrix key needs a non-empty list of values",
                             hint=f"{key}: [a, b]")
        if any(isinstance(v, dict | list) or v is None for v in values):
            raise InputError(f"{mat_loc.at(matrix, key)}: matrix values are single values (text or numbers)")
        if key in options:
            raise InputError(f"{mat_loc.at(matrix, key)}: '{shown_key(key) or '<key>'}' is set both in the matrix "
                             "and in the options")
        if key not in command_keys and not (_uses(entry.get("name"), key) or _uses(raw, key)
                                            or any(_uses(v, key) for v in options.values())):
            name = shown_key(key) or "<key>"
            raise InputError(f"{mat_loc.at(matrix, key)}: '{name}' is no option of recon {kind.value} and no "
                             f"{{{name}}} uses it", hint="use it as {" + name + "} in the name or a value")
    ex_loc = loc.at(entry, "exclude")
    excludes = entry.get("exclude") or []
    if not isinstance(excludes, list) or any(not isinstance(x, dict) for x in excludes):
        raise InputError(f"{ex_loc}: exclude is a list of mappings, e.g. [{{object: mug, seed: 1}}]")
    for x in excludes:
        for k in x:
            if k not in matrix:
                raise InputError(f"{ex_loc}: '{shown_key(k) or '<key>'}' is not a matrix key")
    keys = [str(k) for k in matrix]
    count = math.prod(len(v) for v in matrix.values())
    if count - len(excludes) > MAX_JOBS:  # counted before anything is expanded
        raise InputError(f"{mat_loc}: expands to {count:,} combinations (at most {MAX_JOBS:,} jobs)",
                         hint="split the batch or use fewer matrix values")
    combos = [dict(zip(keys, vals, strict=True)) for vals in itertools.product(*matrix.values())]
    combos = [c for c in combos if not any(all(_format_number(c[k]) == _format_number(v) for k, v in x.items())
                                           for x in excludes)]
    if len(combos) > MAX_JOBS:
        raise InputError(f"{mat_loc}: expands to {len(combos)} jobs (at most {MAX_JOBS})")

    if "timeout_s" in entry:
        timeout = _number(entry["timeout_s"], loc.at(entry, "timeout_s"), positive=True)
    else:
        timeout = overrides.timeout_s or (DEFAULT_TIMEOUT_S if defaults.timeout_s is None else defaults.timeout_s)
    if "retries" in entry:
        retries = _whole(entry["retries"], loc.at(entry, "retries"))
    elif overrides.retries is not None:
        retries = overrides.retries
    else:
        retries = DEFAULT_RETRIES if defaults.retries is None else defaults.retries
    own = _expectations(entry.get("expect"), loc.at(entry, "expect"), kind)
    expect = defaults.expect.only(MEASURES[kind]).merged(own)
    env = defaults.env + _env(entry.get("env"), loc.at(entry, "env"))
    default_options = {k: v for k, v in defaults.options.items()
                       if k in command_keys and k not in options and k not in matrix}
    name_template = entry.get("name")
    if name_template is not None and not isinstance(name_template, str):
        raise InputError(f"{loc.at(entry, 'name')}: a job name is text")

    jobs = []
    for combo in combos or [{}]:
        values = {k: _format_number(v) for k, v in combo.items()}
        opts: dict = dict(default_options)
        where: dict[str, Loc] = {k: Loc(path, None, f"defaults.options.{k}") for k in default_options}
        for k, v in options.items():
            opts[k] = _substitute(v, values, opt_loc.at(options, k)) if isinstance(v, str) else v
            where[k] = opt_loc.at(options, k)
        for k, v in combo.items():
            if k in command_keys:
                opts[k] = v
                where[k] = mat_loc.at(matrix, k)
        args: tuple[str, ...] = ()
        if kind.takes_script:
            script = _resolve_script(_substitute(raw, values, loc.at(entry, kind.value)), base,
                                     loc.at(entry, kind.value))
            args = (str(script),)
            stem = script.stem
        else:
            stem = kind.value
        args += _option_args(kind, opts, where, commands)
        suffix = "".join(f"-{k}={v}" for k, v in values.items())
        if name_template is not None:
            name = _substitute(name_template, values, loc.at(entry, "name"))
            name += "" if _PLACEHOLDER.search(name_template) else suffix
        else:
            name = stem + suffix
        views = (24 if str(opts.get("views", "single")) == "eq-4.1" else 1) if kind is JobKind.CAPTURE else None
        jobs.append(JobSpec(_job_name(name, loc.at(entry, "name")), kind, args, base, timeout, retries, expect, env,
                            str(loc), views, tuple(values.items())))
    return jobs


def load_batch_file(path: Path, commands: Commands, overrides: Overrides = Overrides()) -> BatchSpec:
    """Read, expand and check a batch file (its jobs' options against ``commands``)."""
    path = Path(path)
    data = read_yaml(path, "batch file", hint="see docs/batch.md for the format")
    check_schema(data, "batch", path)
    top = Loc(path)
    if not isinstance(data, dict):
        raise InputError(f"{path}: a batch file is a mapping with 'jobs:'", hint="see docs/batch.md")
    _known_keys(data, _TOP_KEYS, top)
    d_loc = top.at(data, "defaults")
    d = _mapping(data.get("defaults"), d_loc, "defaults")
    _known_keys(d, _DEFAULT_KEYS, d_loc)
    defaults = _Defaults(
        _expectations(d.get("expect"), d_loc.at(d, "expect"), None), _env(d.get("env"), d_loc.at(d, "env")),
        _mapping(d.get("options"), d_loc.at(d, "options"), "options"),
        _number(d["timeout_s"], d_loc.at(d, "timeout_s"), positive=True) if "timeout_s" in d else None,
        _whole(d["retries"], d_loc.at(d, "retries")) if "retries" in d else None)
    for key in defaults.options:
        if key in RESERVED or not any(key in commands.options(k) for k in JobKind):
            raise InputError(f"{d_loc.at(d, 'options').at(defaults.options, key)}: no job command has this "
                             "option, or a batch sets it itself")
    entries = data.get("jobs")
    if not isinstance(entries, list) or not entries:
        raise InputError(f"{top.at(data, 'jobs')}: needs a non-empty list of jobs", hint="see docs/batch.md")
    jobs: list[JobSpec] = []
    for i, entry in enumerate(entries):
        loc = top.at(data, "jobs").item(entries, i)
        if not isinstance(entry, dict):
            raise InputError(f"{loc}: a job is a mapping, e.g. '- run: smoke.xml'")
        jobs += _expand(path, entry, loc, defaults, overrides, commands)
        if len(jobs) > MAX_JOBS:  # before the next entry is expanded
            raise InputError(f"{loc}: the batch has more than {MAX_JOBS:,} jobs with this entry",
                             hint="split the batch")
    name = data.get("name", path.stem)
    return BatchSpec(_job_name(str(name), top.at(data, "name")), _unique(jobs), (str(path),))


def script_job(script: Path, overrides: Overrides) -> JobSpec:
    """A ``recon run SCRIPT`` job with default settings (a script given on the command line)."""
    script = Path(script)
    if not script.is_file():
        raise FileError(f"script {script} does not exist")
    return JobSpec(_job_name(script.stem, str(script)), JobKind.RUN, (str(script.resolve()),), Path.cwd().resolve(),
                   overrides.timeout_s or DEFAULT_TIMEOUT_S,
                   DEFAULT_RETRIES if overrides.retries is None else overrides.retries, source=str(script))


def _unique(jobs: list[JobSpec]) -> tuple[JobSpec, ...]:
    seen: dict[str, JobSpec] = {}
    for j in jobs:
        if j.name in seen:
            raise InputError(f"{j.source}: job name '{j.name}' is used twice (also {seen[j.name].source})",
                             hint="give the jobs distinct names (name: ..., with {key} for matrix values)")
        seen[j.name] = j
    if len(jobs) > MAX_JOBS:
        raise InputError(f"the batch has {len(jobs)} jobs (at most {MAX_JOBS})")
    return tuple(jobs)


def shipped_batch(path: Path) -> Path:
    """``path``, or the shipped batch of that name (``ci.yaml``, ``batches/ci.yaml``) where no
    such file is here: the shipped batches travel with the package."""
    if not path.exists() and path.parent.name in ("", BATCHES_DIR.name) and (BATCHES_DIR / path.name).is_file():
        return BATCHES_DIR / path.name
    return path


def load_batch(sources: list[str], commands: Commands, overrides: Overrides = Overrides()) -> BatchSpec:
    """The batch of the command line: batch files (.yaml/.yml), scripts (.xml) and globs of
    them, in the order given (the jobs' options checked against ``commands``)."""
    if not sources:
        raise InputError("no batch file or script given", hint="recon batch BATCH.yaml or recon batch 'dir/*.xml'")
    jobs: list[JobSpec] = []
    names: list[str] = []
    for src in sources:
        paths = [src]
        if glob.has_magic(src):
            paths = sorted(glob.glob(src, recursive=True))
            if not paths:
                raise FileError(f"{src} matches no file")
        for p in map(Path, paths):
            if p.suffix.lower() in (".yaml", ".yml"):
                spec = load_batch_file(shipped_batch(p), commands, overrides)
                jobs += spec.jobs
                names.append(spec.name)
            elif p.suffix.lower() == ".xml":
                jobs.append(script_job(p, overrides))
            elif p.is_dir():
                raise FileError(f"{p} is a folder", hint=f"give its scripts as '{p}/*.xml'")
            else:
                raise FileError(f"{p}: not a batch file (.yaml) or a script (.xml)")
    name = names[0] if len(names) == 1 and len(sources) == 1 else "batch"
    if overrides.record:
        jobs = [dataclasses.replace(j, args=(*j.args, "--record"))
                if "record" in commands.options(j.kind) and "--record" not in j.args else j for j in jobs]
    return BatchSpec(name, _unique(jobs), tuple(sources))
