"""Files and video of a SimulationResult: CSV (with a JSON sidecar), Parquet and netCDF (an
xarray Dataset), each carrying the same provenance (`provenance`), written whole or not at all;
and an animation of the recorded shapes (MP4 through imageio-ffmpeg, or GIF), with the tables
it draws (`animation_tables`, the robot's `edge_table`) and those tables, as written and read
back, put into a result to draw from (`replay`)."""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import io
import json
import re
import subprocess
import tempfile
import textwrap
import warnings
from pathlib import Path
from typing import Mapping, Optional, Sequence, Tuple

import numpy as np
import pandas as pd

from . import drawing
from .checks import is_whole
from .extras import require
from .geometry import ARC, CENTRE, LIMB, SPOKE, build_topology
from .params import PARAMETER_UNITS, StarParams, check_number, parameter_column
from .provenance import (TABLE_SHA256, TEMPORARY_MARK, code_record, file_path, machine,
                         provenance_json, require_folder, table_stamp, write_atomic)

# the public names (docs/api.md), those the studies use among them (tests/test_layering.py)
__all__ = ["to_xarray", "summary_of_dataset", "read_provenance", "animate", "column_unit",
           "column_units", "parquet_bytes", "GIF_MOST_FPS", "edge_table", "animation_tables",
           "replay", "SHAPE_DECIMALS"]

PROVENANCE_KEY = "taichi_star"
"""Key of the provenance in a Parquet file's schema metadata (JSON)."""
TABLES = ("summary", "trajectory", "sensitivities", "trajectory_sensitivities")
"""The tables `to_parquet` and `to_csv` write (the last two: a run with sensitivities)."""
ANIMATION_FPS = (1, 1000)
"""Allowed frame rates of `animate`, frames per second (lowest, highest)..."""
GIF_MOST_FPS = 50
"""... at most this for a GIF: its frame delays are whole hundredths of a second (15 fps plays
at 16.7), and viewers play delays under 20 ms as 100 ms (an audit: 60 fps played at 100 and
above 100 fps at ~10)."""
ANIMATION_SIZE_PX = (100, 8192)
"""Allowed widths of `animate`'s movie, pixels (lowest, highest): a 1-inch figure at 100 dpi
up to what a frame of 8192² RGBA pixels (268 MB) still holds in memory."""
HEADING_LEAST_PT = 4.0
"""Smallest font of an animation's heading, points: a heading that does not fit the movie's
width at it is wrapped instead (`_fit_heading`)."""
HEADING_WIDTH_SHARE = 0.96
"""Share of the movie's width that its heading's widest line may take."""
PANEL_TITLE_PT = 9.0
"""Font of an animation's panel titles where its heading keeps its full size, points."""
PANEL_TITLE_PAD_PT = 6.0
"""Gap between a panel and its title at PANEL_TITLE_PT, points (matplotlib's default); it
shrinks with the title."""

UNITS = {"_seconds_per_wall_s": "1", "_seconds_per_s": "1", "_per_wall_s": "1/s", "_per_s": "1/s",
         "_gb_s": "GB/s", "_mm_s": "mm/s", "_mm": "mm", "_deg_s": "degree/s", "_deg": "degree",
         "_ms": "ms", "_us": "us", "_n_s_m": "N*s/m", "_s": "s", "_m": "m"}
"""Units of result columns by name suffix, the longest match counting (`column_unit`):
simulated seconds per wall second are a ratio, robot-steps per second a rate, a jet's impulse
N·s per metre of height."""
PARAMETER_COLUMN_UNITS = {parameter_column(name): unit for name, unit in PARAMETER_UNITS.items()}
"""Units of the numeric parameter columns (youngs_modulus_pa: Pa, alpha: 1)."""


DERIVATIVE_COLUMN = re.compile(r"^d\((?P<output>.+)\)/d\((?P<field>[a-z_]+)"
                               r"(\[(?P<index>\d+)\])?\)$")
"""A sensitivity column's name, "d(x_mm)/d(youngs_modulus)" or "d(x_mm)/d(actuator_gains[3])"."""


def column_unit(name: str) -> str:
    """The unit of a result column, from the parameter columns or its suffix ("" if none); a
    sensitivity column's is its output's over its field's ("mm/Pa", "(mm/s)/m"; the output's
    alone for a dimensionless field)."""
    derivative = DERIVATIVE_COLUMN.match(name)
    if derivative:
        output = column_unit(derivative["output"])
        field = PARAMETER_UNITS.get(derivative["field"], "")
        if not output or not field:
            return ""
        if field == "1":
            return output
        # a unit of more than one factor in brackets: "mm/Pa*s" reads as mm·s/Pa (as UDUNITS,
        # which netCDF tools use, reads it), the derivative by a drag in Pa·s (an audit)
        return "/".join(f"({unit})" if "/" in unit or "*" in unit else unit
                        for unit in (output, field))
    if name in PARAMETER_COLUMN_UNITS:
        return PARAMETER_COLUMN_UNITS[name]
    # the longest first, whatever the table's order (the first match counted, and
    # impulse_x_n_s_m, matching "_m", was in metres: an audit)
    for suffix in sorted(UNITS, key=len, reverse=True):
        if name.endswith(suffix):
            return UNITS[suffix]
    return ""


def column_units(columns) -> dict:
    """{column: unit} for the columns whose unit the name tells (see `column_unit`)."""
    return {name: column_unit(name) for name in columns if column_unit(name)}


def provenance(result, columns=None) -> dict:
    """What produced `result`, as the studies' CSV sidecars record it: the code and runtime
    (`provenance.code_record`, taken as the file is written: taichi_star_version, git_commit,
    git_dirty, a dirty checkout's git_changes_sha256, Taichi and Python versions), the `date`
    the result was made (`SimulationResult.made_at`) and the date the file was `written`; the
    `machine` (`provenance.machine`:
    CPU model, cores, vector instruction sets, caches, GPUs, platform) and the `arch` the run
    used (None for a result that does not say); for a `run_batch` result whose run store
    more than one code version wrote, `code_versions` (each with the chunks it made: the code
    record above is the writer's alone); the call's `arguments` (`SimulationResult.arguments`:
    duration, records, steady_from_cycle, sensitivities, ...); solver (every SolverConfig field);
    parameters (the StarParams fields equal across the instances, by field name) and
    varying_parameters (the fields that differ, whose values are in the summary's columns: the
    other tables name each row's instance, or, the sensitivities', are in instance order);
    units of the table's `columns` (default the summary's); with the result's `timing` (a
    `simulate` call's), its phases in s (compilation apart), its robot-steps and
    robot_steps_per_s (null for a run of no measurable time: every number JSON cannot hold
    is written as null, `provenance.provenance_json`)."""
    summary = result.summary
    parameters, varying = {}, []
    for name, column in StarParams.columns().items():
        if column not in summary:
            continue
        if len(summary) and summary[column].nunique(dropna=False) == 1:
            value = summary[column].iloc[0]
            parameters[name] = value.item() if isinstance(value, np.generic) else value
        else:
            varying.append(name)
    timing = {}
    if result.timing is not None:
        timing = {"timing": {**dataclasses.asdict(result.timing),
                             "robot_steps_per_s": result.timing.robot_steps_per_s}}
    mixed = {} if result.code_versions is None else {"code_versions": result.code_versions}
    called = {} if result.arguments is None else {"arguments": result.arguments}
    # the run's own date; the file's is `written`
    record = code_record()
    dates = {"date": getattr(result, "made_at", None) or record["date"],
             "written": record["date"]}
    return {**record, **dates, **mixed, "machine": machine(), "arch": result.arch,
            **called, "solver": dataclasses.asdict(result.solver),
            "parameters": parameters, "varying_parameters": varying,
            "units": column_units(summary.columns if columns is None else columns), **timing}


def _table(result, table: str) -> pd.DataFrame:
    if table not in TABLES:
        raise ValueError(f"table must be one of {list(TABLES)}, got {table!r}")
    frame = getattr(result, table)
    if frame is None:  # the sensitivities of a run without them
        raise ValueError(f"table {table!r}: this result has none (simulate with "
                         f"sensitivities=... for it)")
    # the sensitivities name no instance: their rows are matched to the summary's by position,
    # so they are written in the run's order whatever a user's sort did to the frame (a sort
    # in place wrote another instance's derivatives on a row: an audit, 2026-12)
    return in_instance_order(frame, table) if table == "sensitivities" else frame


def parquet_bytes(frame: pd.DataFrame, metadata: Mapping) -> bytes:
    """`frame` as a Parquet file (typed columns, every float bit for bit) with `metadata` as
    JSON under the schema metadata key "taichi_star". Values Parquet has no type for (objects
    other than text) are stored as their text. Needs pyarrow (the `io` extra: ImportError
    naming it otherwise)."""
    pa = require("pyarrow", "io")
    pq = require("pyarrow.parquet", "io")

    frame = frame.assign(**{column: frame[column].map(str) for column in frame.columns
                            if frame[column].dtype == object
                            and not frame[column].map(lambda v: isinstance(v, str)).all()})
    table = pa.Table.from_pandas(frame, preserve_index=False)
    schema_metadata = {**(table.schema.metadata or {}),
                       PROVENANCE_KEY.encode(): provenance_json(metadata).encode()}
    sink = pa.BufferOutputStream()
    # a CRC per data page: `read_provenance` verifies them, so that a flipped byte in the
    # values is an error rather than another number (390 of a file's 42,648 single-byte
    # flips read back as other values without one: an audit, 2026-12)
    pq.write_table(table.replace_schema_metadata(schema_metadata), sink,
                   write_page_checksum=True)
    return sink.getvalue().to_pybytes()


def to_parquet(result, path, table: str = "summary") -> Path:
    """Write the result's `table` (one of `TABLES`: "summary", "trajectory", and for a run
    with sensitivities "sensitivities" or "trajectory_sensitivities") as Parquet, whole or not
    at all, its `provenance` in the file's metadata (`read_provenance`). Returns the path."""
    path = file_path(path, "path of the Parquet file")
    frame = _table(result, table)
    write_atomic(path, parquet_bytes(frame, provenance(result, frame.columns)), failure=OSError,
                 sidecar=_stale_csv_sidecar(path))
    return path


def _stale_csv_sidecar(path: Path) -> Optional[Tuple[Path, None]]:
    """`write_atomic`'s sidecar to remove where an earlier CSV of this name left its sidecar
    (a JSON object with the table's SHA-256): a Parquet or netCDF file written over it
    describes itself, and the sidecar would describe a table no longer there (it stayed; an
    audit, 2026-12). None otherwise: a JSON file of any other kind is left alone."""
    sidecar = Path(f"{path}.json")
    try:
        facts = json.loads(sidecar.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return (sidecar, None) if isinstance(facts, dict) and TABLE_SHA256 in facts else None


CSV_COMPRESSIONS = {".gz": "gzip", ".bz2": "bz2", ".xz": "xz", ".zip": "zip"}
"""The compressions `to_csv` writes, by the path's suffix, as pandas' own `to_csv` chooses them
(and `read_csv` reads them back by the same suffix): "run.csv.gz" held plain text, which
`read_csv` refused as a damaged gzip file (an audit, 2026-12). pandas' other suffixes (.zst,
.tar) are refused: their readers are not in the standard library."""
CSV_REFUSED_SUFFIXES = (".zst", ".tar", ".tar.gz", ".tar.bz2", ".tar.xz")
"""pandas' names of the compressions `to_csv` refuses ("x.tar.gz" is a tar archive to pandas,
not a gzip stream)."""


def csv_bytes(frame: pd.DataFrame, path: Path) -> bytes:
    """The bytes of `frame` as CSV, compressed as `path`'s suffix says (`CSV_COMPRESSIONS`),
    the same bytes for the same table (a gzip stream's time stamp 0); ValueError naming the
    path for a suffix of pandas' that `to_csv` does not write."""
    refused = [end for end in CSV_REFUSED_SUFFIXES if path.name.lower().endswith(end)]
    if refused:
        raise ValueError(f"path {str(path)!r}: to_csv writes plain CSV or CSV compressed as "
                         f"{', '.join(CSV_COMPRESSIONS)} say, not {refused[-1]}")
    method = CSV_COMPRESSIONS.get(path.suffix.lower())
    if method is None:
        return frame.to_csv(index=False).encode()
    options = {"gzip": {"mtime": 0}, "zip": {"archive_name": path.stem}}.get(method, {})
    buffer = io.BytesIO()
    frame.to_csv(buffer, index=False, compression={"method": method, **options})
    return buffer.getvalue()


def to_csv(result, path, table: str = "summary") -> Path:
    """Write the result's `table` as CSV (floats to the last bit: pandas' `read_csv` gives them
    back exactly; compressed where the path ends in .gz, .bz2, .xz or .zip, as pandas' own
    `to_csv` would, `csv_bytes`) and its `provenance` as the JSON sidecar `<path>.json`, with
    the table's rows and the file's SHA-256 (`read_provenance` checks them), both whole or not
    at all: a full disk leaves the previous pair, a kill at worst the new table without a
    sidecar, never beside the previous one's (`write_atomic`). Returns the path."""
    path = file_path(path, "path of the CSV file")
    frame = _table(result, table)
    data = csv_bytes(frame, path)
    facts = {**provenance(result, frame.columns), **table_stamp(len(frame), data)}
    write_atomic(path, data, failure=OSError,
                 sidecar=(Path(f"{path}.json"),
                          (provenance_json(facts, indent=2) + "\n").encode()))
    return path


def to_netcdf(result, path) -> Path:
    """Write `to_xarray(result)` as a netCDF file, whole or not at all. Returns the path."""
    path = file_path(path, "path of the netCDF file")
    require_folder(path)
    require("netCDF4", "io")
    dataset = to_xarray(result)
    # netCDF's library reports a full disk as a RuntimeError ("NetCDF: HDF error") or as a
    # PermissionError (below)
    # a Fletcher-32 checksum per chunk of every numeric variable: HDF5 checks it whenever the
    # file is read, by any reader (a flipped byte read back as another value: an audit)
    # (checksums need chunked variables: a small file's per-variable chunk indexes make it
    # ~120 kB larger, a fixed cost per variable)
    encoding = {name: {"fletcher32": True} for name, variable in dataset.variables.items()
                if variable.dtype.kind in "biufc" and variable.ndim}
    with _scratch_file(path, (OSError, RuntimeError)) as scratch:
        try:
            dataset.to_netcdf(scratch, encoding=encoding)
        except PermissionError as error:
            # netCDF4 reports a full disk (ENOSPC) as EACCES, "Permission denied" (an audit);
            # the scratch folder it writes into was created just now, so it is writable
            raise OSError(error.errno, f"netCDF4 reported: {error.strerror}; the folder is "
                                       f"writable, so the disk may be full") from None
        data = scratch.read_bytes()
    write_atomic(path, data, failure=OSError, sidecar=_stale_csv_sidecar(path))
    return path


@contextlib.contextmanager
def _scratch_file(path: Path, failures: tuple):
    """A file to draw `path` into first, in a scratch folder beside it (".NAME.tmp-...":
    `provenance.is_temporary`, removed after, left by a kill); `failures` raised while it is
    written become an OSError naming `path` ("cannot write r.nc (No space left on device)"),
    not the scratch folder."""
    try:
        with tempfile.TemporaryDirectory(dir=path.parent,
                                         prefix=f".{path.name}{TEMPORARY_MARK}") as folder:
            yield Path(folder) / path.name
    except failures as error:
        if isinstance(error, subprocess.CalledProcessError):
            program = Path(str(error.cmd[0])).name if error.cmd else "the encoder"
            reason = f"{program} exited with status {error.returncode}"
        elif isinstance(error, OSError) and error.strerror:
            reason = error.strerror
        else:
            reason = (str(error).splitlines() or [type(error).__name__])[0]
        raise OSError(f"cannot write {path.name} ({reason})") from None


def _file_kind(path: Path) -> str:
    """"parquet", "netcdf" or "csv": by the file's first bytes where they say (the writers take
    any name: "x.pq" was read as a CSV whose sidecar did not exist), else a CSV where its
    sidecar lies beside it (a table written as "x.parquet" by `to_csv` was read as a damaged
    Parquet file: an audit, 2026-12), else by its suffix (a damaged ".parquet" is then named
    as one)."""
    try:
        with open(path, "rb") as file:
            head = file.read(8)
    except OSError:
        head = b""
    if head.startswith(b"PAR1"):
        return "parquet"
    if head.startswith((b"\x89HDF\r\n\x1a\n", b"CDF")):
        return "netcdf"
    if Path(f"{path}.json").is_file():
        return "csv"
    return {".parquet": "parquet", ".nc": "netcdf"}.get(path.suffix.lower(), "csv")


def _verify_page_checksums(path: Path):
    """ValueError naming the Parquet file `path` where a page of its values fails its CRC
    (`parquet_bytes` writes them), read a batch at a time (a whole table could need gigabytes
    of memory: a review, 2026-12); a file written without CRCs passes."""
    pq = require("pyarrow.parquet", "io")
    pyarrow = require("pyarrow", "io")
    try:
        for _ in pq.ParquetFile(path, page_checksum_verification=True).iter_batches():
            pass
    except (OSError, pyarrow.ArrowException) as error:
        if isinstance(error, OSError) and "checksum" not in str(error).lower():
            raise  # the file cannot be read (an I/O error), not damaged values
        raise ValueError(f"{path}: its values are damaged ({str(error).splitlines()[0]}); its "
                         f"provenance is intact but describes other values") from None


def read_provenance(path) -> dict:
    """The provenance written with a result file: from a Parquet file's metadata, a netCDF
    file's attributes (`provenance`) or a CSV file's sidecar. OSError where the file cannot be
    read; ValueError naming it where it holds no provenance (damaged, not a JSON object, or not
    written by `to_parquet`, `to_netcdf` or `to_csv`), where a Parquet file's values fail their
    page checksums (`_verify_page_checksums`), or where a CSV is no longer the table its sidecar
    describes (its SHA-256 differs: damaged or edited since). A netCDF file's values carry
    checksums that HDF5 checks whenever they are read (an error, from any reader)."""
    path = file_path(path, "path of a result file")
    kind = _file_kind(path)
    source = path if kind in ("parquet", "netcdf") else Path(f"{path}.json")
    if kind == "csv" and path.is_file() and not source.exists():
        # a plain CSV, readable: no provenance, as a plain Parquet file has none (it raised
        # FileNotFoundError for the sidecar, an OSError where the docstring says ValueError)
        raise ValueError(f"{path}: no taichi_star provenance beside it (no sidecar "
                         f"{source.name}: not written by to_csv)")
    try:
        if kind == "parquet":
            pq = require("pyarrow.parquet", "io")
            facts = json.loads(pq.read_schema(path).metadata[PROVENANCE_KEY.encode()])
        elif kind == "netcdf":
            xr = require("xarray", "io")
            with xr.open_dataset(path) as dataset:
                facts = json.loads(dataset.attrs["provenance"])
        else:
            facts = json.loads(source.read_text())
    except ImportError:
        raise
    except OSError as error:
        if error.errno is None or error.errno >= 0:
            raise
        # netCDF's library reports a damaged file as a negative error number ("NetCDF: HDF
        # error"), not as an operating-system error
        raise ValueError(f"{source}: no taichi_star provenance in it (damaged: "
                         f"{error.strerror or error})") from None
    except Exception as error:  # noqa: BLE001 -- pyarrow's, xarray's and json's errors vary
        reason = str(error).splitlines()[0] if str(error) else ""
        raise ValueError(f"{source}: no taichi_star provenance in it ({type(error).__name__}"
                         f"{': ' + reason if reason else ''})") from None
    if not isinstance(facts, dict):  # valid JSON, yet no record ("[1]"): its readers call .get
        raise ValueError(f"{source}: no taichi_star provenance in it (not a JSON object)")
    if kind == "parquet":
        _verify_page_checksums(path)
    written = facts.get(TABLE_SHA256)
    if written is not None and hashlib.sha256(path.read_bytes()).hexdigest() != written:
        raise ValueError(f"{path}: not the table its provenance {source.name} describes (its "
                         f"SHA-256 differs: damaged or edited since it was written)")
    return facts


def summary_of_dataset(dataset) -> pd.DataFrame:
    """The per-instance table of a `to_xarray` Dataset (or one read from netCDF): every
    variable and coordinate along `instance` alone but the sensitivities, as columns (the
    `instance` coordinate first where the summary had it as a column: a `run_batch`
    result's; else the index, as `simulate`'s summary numbers its rows, so that the rows of a
    selection, `isel(instance=[1, 3])`, keep their instances: they were numbered 0 and 1, an
    audit, 2026-12); `StarParams.from_row` reads its rows. ValueError for anything else (a
    path: open it with `xarray.open_dataset` first)."""
    xr = require("xarray", "io")
    if not isinstance(dataset, xr.Dataset) or "instance" not in dataset.coords:
        raise ValueError(f"dataset must be an xarray Dataset of `to_xarray` (or read from "
                         f"`to_netcdf`'s file with xarray.open_dataset), with an 'instance' "
                         f"coordinate; got {type(dataset).__name__}")
    names = [name for name in [*dataset.coords, *dataset.data_vars]
             if dataset[name].dims == ("instance",) and name != "instance"
             and not dataset[name].attrs.get("sensitivity")]
    instances = dataset["instance"].to_numpy()
    index = None
    if dataset["instance"].attrs.get("summary_column") == 1:
        names.insert(0, "instance")
    elif not np.array_equal(instances, np.arange(len(instances))):
        index = pd.Index(instances)
    return pd.DataFrame({name: dataset[name].to_numpy() for name in names}, index=index)


def _netcdf_units(name: str, values: np.ndarray) -> str:
    """The `units` attribute of a per-instance variable: its column's unit, else "1" for
    numbers (dimensionless, counts, flags: the project's unit of a pure number) and "" for
    text, which has no unit."""
    unit = column_unit(name)
    if unit:
        return unit
    return "1" if values.dtype.kind in "biuf" else ""


RECORD_VARIABLES = {"x_mm": "centroid_x_mm", "y_mm": "centroid_y_mm",
                    "heading_deg": "record_heading_deg"}
"""The Dataset's variable of each trajectory column: apart from the summary's (its
heading_deg is the whole run's rotation, the record's the rotation at each record)."""


def _variable_of_column(column: str, per_record: bool = False) -> str:
    """A sensitivity column's name as a netCDF variable's, which cannot hold "/":
    "d(displacement_x_mm)/d(actuator_gains[2])" → "d_displacement_x_mm__d_actuator_gains_2";
    `per_record` (a trajectory sensitivity) names the output by its trajectory variable
    (`RECORD_VARIABLES`): "d(heading_deg)/d(alpha)" → "d_record_heading_deg__d_alpha", apart
    from the summary's "d_heading_deg__d_alpha" (which it overwrote until 2026-12)."""
    parts = DERIVATIVE_COLUMN.match(column)
    index = "" if parts["index"] is None else f"_{parts['index']}"
    output = RECORD_VARIABLES[parts["output"]] if per_record else parts["output"]
    return f"d_{output}__d_{parts['field']}{index}"


def in_instance_order(frame: pd.DataFrame, name: str) -> pd.DataFrame:
    """One of a result's tables (`name`: "summary", "sensitivities", ...) in the order the run
    made it, its rows numbered from 0 again: a user's `sort_values(inplace=True)` on the
    result's own frame keeps the rows' labels, and readers that match rows by position
    (`to_xarray`, `SimulationResult.sensitivity`) gave every instance another's values (an
    audit, 2026-12). ValueError where the labels no longer number the rows 0, 1, ... (a reset
    or new index set in place), naming the table."""
    ordered = frame.sort_index()
    if not ordered.index.equals(pd.RangeIndex(len(ordered))):
        raise ValueError(f"result.{name}: its rows are no longer labelled 0..{len(frame) - 1} "
                         f"in the run's order (its index was changed in place); work on a copy "
                         f"(result.{name}.sort_values(...) without inplace)")
    return ordered.reset_index(drop=True)


def to_xarray(result):
    """The result as an xarray Dataset: per instance (dim `instance`) every summary column, the
    parameters as coordinates; per record (dims `instance`, `time`) the centroid and heading;
    with recorded shapes, `positions` (time, instance, node, xy) in m; with sensitivities,
    each of their columns (`sensitivities` per instance, `trajectory_sensitivities` per record)
    as a variable "d_OUTPUT__d_PARAMETER" (a record's OUTPUT named by its variable:
    centroid_x_mm, centroid_y_mm, record_heading_deg) whose attributes hold the column's name
    ("column"),
    its units and sensitivity = 1 (`summary_of_dataset` leaves them out). Every variable and
    coordinate carries a `units` attribute: its column's (`column_unit`), "1" for a
    dimensionless number, count, flag or index (instance, node), "" for text (gait, status,
    the labels of xy); the dataset's attributes hold the `provenance` as JSON (`provenance`)
    and its main entries one by one (taichi_star_version, git_commit, git_dirty, arch, the
    solver's integrator, dt_s, adaptive, precision)."""
    xr = require("xarray", "io")

    summary = in_instance_order(result.summary, "summary")
    parameter_columns = set(StarParams.columns().values())
    # a batch's summary (`batch.run_batch`) names its instances in a column of its own: that
    # is the coordinate; a plain result's instances are its rows
    instances = (summary["instance"].to_numpy() if "instance" in summary
                 else np.arange(len(summary)))
    # summary_column: whether the summary had the column, so that `summary_of_dataset` gives a
    # batch's back (it dropped it) and adds none to a plain result's (1/0: netCDF has no bool)
    coordinates = {"instance": ("instance", instances,
                                {"units": "1", "summary_column": int("instance" in summary)})}
    variables = {}
    for name in summary.columns.drop("instance", errors="ignore"):
        values = summary[name].to_numpy()
        if values.dtype == object or pd.api.types.is_string_dtype(summary[name]):
            values = summary[name].astype(str).to_numpy()
        into = coordinates if name in parameter_columns else variables
        into[name] = ("instance", values, {"units": _netcdf_units(name, values)})
    trajectory = result.trajectory
    if len(trajectory):
        times = np.sort(trajectory["t_s"].unique())
        coordinates["time"] = ("time", times, {"units": "s"})
        table = trajectory.pivot(index="instance", columns="t_s")
        for name, variable in RECORD_VARIABLES.items():
            # an instance without records (a resumed batch's chunk stored before the run store
            # kept trajectories has its summary alone) gets NaN rows
            variables[variable] = (
                ("instance", "time"),
                table[name].reindex(index=instances, columns=times).to_numpy(),
                {"units": column_unit(name)})
    if result.sensitivities is not None:
        sensitivities = in_instance_order(result.sensitivities, "sensitivities")
        for name in sensitivities.columns:
            variables[_variable_of_column(name)] = (
                "instance", sensitivities[name].to_numpy(),
                {"units": column_unit(name), "column": name, "sensitivity": 1})
        derivatives = result.trajectory_sensitivities
        if len(derivatives):
            table = derivatives.pivot(index="instance", columns="t_s")
            for name in derivatives.columns.drop(["instance", "t_s"]):
                variables[_variable_of_column(name, per_record=True)] = (
                    ("instance", "time"),
                    table[name].reindex(index=instances, columns=times).to_numpy(),
                    {"units": column_unit(name), "column": name, "sensitivity": 1})
    if result.shapes is not None:
        coordinates["node"] = ("node", np.arange(result.shapes.shape[2]), {"units": "1"})
        coordinates["xy"] = ("xy", ["x", "y"], {"units": ""})
        # a copy: the dataset's variable was the result's own array, so editing it changed
        # the result's shapes (an audit, 2026-12)
        variables["positions"] = (("time", "instance", "node", "xy"), np.array(result.shapes),
                                  {"units": "m"})
    dataset = xr.Dataset(variables, coords=coordinates)
    facts = provenance(result)
    dataset.attrs.update({"provenance": provenance_json(facts),
                          "taichi_star_version": facts["taichi_star_version"],
                          "git_commit": facts["git_commit"] or "unknown",
                          "git_dirty": str(facts["git_dirty"]).lower(),
                          "arch": facts["arch"] or "unknown",
                          "integrator": result.solver.integrator, "dt_s": result.solver.dt,
                          "adaptive": int(result.solver.adaptive),
                          "precision": result.solver.precision})
    return dataset


def _held_after_failure(shapes: np.ndarray) -> np.ndarray:
    """Shapes (T, B, N, 2) with each instance's records after its failure (NaN) replaced by
    its last finite one: the frozen robot stays drawn, its panel title saying why."""
    held = shapes.copy()
    for index in range(1, len(held)):
        lost = ~np.isfinite(held[index]).all(axis=(1, 2))
        held[index, lost] = held[index - 1, lost]
    return held


EDGE_KIND_NAMES = {SPOKE: "spoke", LIMB: "limb", ARC: "arc"}
"""The words of `edge_table`'s kind column."""
SHAPE_DECIMALS = 5
"""Decimals (of mm) of the node positions in `animation_tables`: 10 nm, under 1e-4 of a pixel
of a 600-pixel movie of the robot (a view ~120 mm wide). Such a number has at most 10
significant digits below 1e5 mm, so a table written at 10 digits reads back exactly; a movie
drawn from it differs from one drawn from the unrounded records only where the GIF's palette
of a frame picks another colour for an anti-aliased edge pixel."""


def edge_table(params: StarParams) -> pd.DataFrame:
    """The edges of the robot `params` (its n_arc and n_limb fix them), one row each in the
    engine's order (for each joint J_k, k = 0..7: the spoke from the hub, the limb from the
    joint outwards, actuator A_{k+1}'s arc towards J_{k+1}): node_a, node_b (node numbers, as
    the recorded shapes' node axis), kind ("spoke", "limb" or "arc"), actuator (m for the
    edges of A_m's arc, 1..8; 0 for spokes and limbs). The (E, 2) node pairs:
    `table[["node_a", "node_b"]].to_numpy()`. ValueError naming params unless it is a
    StarParams."""
    if not isinstance(params, StarParams):
        raise ValueError(f"params must be a StarParams, got {type(params).__name__}")
    topology = build_topology(params)
    return pd.DataFrame({"node_a": topology.edges[:, 0], "node_b": topology.edges[:, 1],
                         "kind": [EDGE_KIND_NAMES[kind] for kind in topology.edge_kind],
                         "actuator": drawing.edge_actuators(topology) + 1})


def animation_tables(result, labels: Sequence[str]) -> Tuple[pd.DataFrame, pd.DataFrame]:
    """What an animation of `result` (a `SimulationResult` with recorded shapes) draws, as two
    long tables, instance b named labels[b] (its gait) in the column gait: the shapes (gait,
    frame, t_s, node, x_mm, y_mm: every node at every record, mm to SHAPE_DECIMALS decimals,
    NaN after a failure) and the centroid (gait, frame, t_s, x_mm, y_mm: relative to its
    start, the result's trajectory). `replay` puts them back into a result, which `animate`
    draws. ValueError without recorded shapes, or unless there is one label per instance, no
    two alike."""
    if result.shapes is None:
        raise ValueError("result has no recorded shapes: simulate with record_interval_s > 0 "
                         "and record_shapes=True")
    labels = list(labels)
    frames, batch, nodes = result.shapes.shape[:3]
    if len(labels) != batch or len(set(labels)) != batch:
        raise ValueError(f"labels must name the {batch} instances, each once, got {labels!r}")
    times = np.sort(result.trajectory["t_s"].unique())
    shapes = result.shapes.transpose(1, 0, 2, 3)                      # (B, frames, N, 2)
    shape_table = pd.DataFrame({
        "gait": np.repeat(labels, frames * nodes),
        "frame": np.tile(np.repeat(np.arange(frames), nodes), batch),
        "t_s": np.tile(np.repeat(times, nodes), batch),
        "node": np.tile(np.arange(nodes), frames * batch),
        "x_mm": np.round(1e3 * shapes[..., 0].ravel(), SHAPE_DECIMALS),
        "y_mm": np.round(1e3 * shapes[..., 1].ravel(), SHAPE_DECIMALS)})
    trajectory = result.trajectory.sort_values(["instance", "t_s"], kind="stable")
    centroid = pd.DataFrame({
        "gait": np.asarray(labels, dtype=object)[trajectory["instance"].to_numpy()],
        "frame": trajectory.groupby("instance").cumcount().to_numpy(),
        "t_s": trajectory["t_s"].to_numpy(), "x_mm": trajectory["x_mm"].to_numpy(),
        "y_mm": trajectory["y_mm"].to_numpy()})
    return shape_table, centroid


def replay(result, shapes: pd.DataFrame, centroid: pd.DataFrame):
    """`result` (a `SimulationResult` of the same robots: its summary and topology are kept)
    with its recorded shapes and trajectory read from the tables of `animation_tables`, as
    written and read back (CSV): `SimulationResult.animate` of it draws the tables. The
    tables' gaits, in order of first appearance, are the instances 0, 1, ...; the trajectory
    holds instance, t_s, x_mm, y_mm and heading_deg, NaN (the tables do not hold it; without
    the column `to_xarray` of the result failed: an audit, 2026-12). ValueError unless the
    shapes hold every node of every frame of each gait once, and the gaits are the result's
    instances."""
    labels = list(dict.fromkeys(shapes["gait"]))
    if len(labels) != len(result.summary):
        raise ValueError(f"shapes hold {len(labels)} gaits, the result "
                         f"{len(result.summary)} instances")
    instance = {label: index for index, label in enumerate(labels)}
    frames, nodes = int(shapes["frame"].max()) + 1, int(shapes["node"].max()) + 1
    index = (shapes["frame"].to_numpy(), shapes["gait"].map(instance).to_numpy(),
             shapes["node"].to_numpy())
    positions = np.full((frames, len(labels), nodes, 2), np.nan)
    positions[index] = shapes[["x_mm", "y_mm"]].to_numpy() / 1e3      # m, as recorded
    counts = np.zeros(positions.shape[:3], dtype=int)
    np.add.at(counts, index, 1)
    if not (counts == 1).all():
        raise ValueError("shapes must hold every node of every frame of each gait once")
    trajectory = pd.DataFrame({"instance": centroid["gait"].map(instance).to_numpy(),
                               "t_s": centroid["t_s"].to_numpy(),
                               "x_mm": centroid["x_mm"].to_numpy(),
                               "y_mm": centroid["y_mm"].to_numpy(),
                               "heading_deg": np.full(len(centroid), np.nan)})
    return dataclasses.replace(result, shapes=positions, trajectory=trajectory)


def animate(result, path, instances: Optional[Sequence[int]] = None, frame: str = "world",
            fps: int = 15, size_px: int = 720, title: Optional[str] = None):
    """Write the recorded shapes of some instances (default: all, up to 16; one panel each) as
    an animation: MP4 (through imageio-ffmpeg's ffmpeg) for a `.mp4` path, GIF for `.gif`.
    Drawn with `taichi_star.drawing`: limbs brown, actuator arcs gray and red while they heat
    (for t0 = `CurvatureProfile.switch_time` s, the gait's actuators: `simulate` fires them at
    0, T, 2T, ..., each heating its `actuator_delays` later), labels A1..A8, the central
    cylinder and a scale bar. `frame` "world" (lab axes, mm, with the centroid's path so far
    drawn in blue) or "body" (following the hub and the body's rotation; no path). `title`
    heads the movie (default none) above the time; in a small movie the heading's font shrinks
    to fit its width, and below HEADING_LEAST_PT its lines wrap. A failed instance's panel names its
    status and failure time and holds its last shape after it (it was an empty panel).
    Returns the path. Raises ValueError without recorded shapes, for an unknown frame or
    suffix, or for instances out of range."""
    matplotlib = require("matplotlib", "video")
    require("PIL", "video")

    # a figure of its own on an Agg canvas, outside pyplot: `matplotlib.use("Agg")` switched a
    # notebook's backend, and its later figures no longer showed (an audit, 2026-12)
    from matplotlib import animation
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    path = file_path(path, "path of the .mp4 or .gif file")
    require_folder(path)
    if result.shapes is None or result.topology is None:
        raise ValueError("animate needs recorded shapes of one topology: simulate with "
                         "record_interval_s > 0 and record_shapes=True")
    if frame not in ("world", "body"):
        raise ValueError(f"frame must be 'world' or 'body', got {frame!r}")
    if path.suffix.lower() not in (".mp4", ".gif"):
        raise ValueError(f"path must end in .mp4 or .gif, got {path.name!r}")
    fps = check_number("fps", fps, *ANIMATION_FPS, integer=True)
    if path.suffix.lower() == ".gif" and fps > GIF_MOST_FPS:
        raise ValueError(f"fps must be at most {GIF_MOST_FPS} for a GIF (its frame delays are "
                         f"whole hundredths of a second), got {fps}: use a .mp4 path")
    size_px = check_number("size_px", size_px, *ANIMATION_SIZE_PX, integer=True)
    batch = result.shapes.shape[1]
    # whole numbers only: int() would take 0.5 for instance 0, True for 1
    if instances is not None and (isinstance(instances, (str, bytes))
                                  or not hasattr(instances, "__iter__")
                                  or np.ndim(instances) != 1):
        raise ValueError(f"instances must be a sequence of integers in [0, {batch}), got "
                         f"{instances!r}")
    chosen = list(range(min(batch, 16))) if instances is None else list(instances)
    if not chosen or any(not is_whole(i)
                         for i in chosen) or min(chosen) < 0 or max(chosen) >= batch:
        raise ValueError(f"instances must be in [0, {batch}), got {instances!r}")
    chosen = [int(i) for i in chosen]
    topology = result.topology
    times = np.sort(result.trajectory["t_s"].unique())
    shapes = _held_after_failure(result.shapes[:, chosen] * 1e3)  # mm
    paths = None
    if frame == "body":
        shapes = _body_frame(shapes, topology)
    else:
        # the trajectory is the centroid relative to its start; the rest shape is symmetric,
        # so the start centroid is the hub's rest position
        start = topology.rest_positions[CENTRE] * 1e3
        paths = [result.trajectory[result.trajectory["instance"] == i].sort_values("t_s")
                 [["x_mm", "y_mm"]].to_numpy() + start for i in chosen]
    params = [StarParams.from_row(result.summary.iloc[i]) for i in chosen]
    hot = [drawing.periodic_hot_actuators(times, p.gait_value.mask, p.period,
                                          p.actuator_profile.switch_time, p.actuator_delays)
           for p in params]
    columns = int(np.ceil(np.sqrt(len(chosen))))
    rows = int(np.ceil(len(chosen) / columns))
    inches = size_px / 100
    fig = Figure(figsize=(inches, inches * rows / columns), dpi=100)
    FigureCanvasAgg(fig)
    axes = fig.subplots(rows, columns, squeeze=False)
    label = fig.suptitle("")
    heading = f"{title}\n" if title else ""

    def heading_at(time_s: float) -> str:
        return f"{heading}t = {time_s:.2f} s ({frame} frame; red: actuators heating)"

    # the latest time writes the longest heading (the times are >= 0); at the smallest sizes
    # a fixed font clipped it at both sides (an audit, 2026-12). The panels' titles shrink
    # with it, or they would run into it
    full_pt = label.get_fontsize()
    wrap, heading_bottom = _fit_heading(fig, label, heading_at(times[-1]))
    label.set_text("")  # empty while the panels are placed below `top`, as before the fit
    panel_pt = max(HEADING_LEAST_PT, PANEL_TITLE_PT * label.get_fontsize() / full_pt)
    low = np.nanmin(shapes, axis=(0, 1, 2))
    high = np.nanmax(shapes, axis=(0, 1, 2))
    centre, half = 0.5 * (low + high), 0.5 * float((high - low).max()) + 10.0
    robots = []
    for slot, ax in enumerate(axes.ravel()):
        ax.set_aspect("equal")
        ax.set_xticks([])
        ax.set_yticks([])
        if slot >= len(chosen):
            ax.axis("off")
            continue
        ax.set_xlim(centre[0] - half, centre[0] + half)
        ax.set_ylim(centre[1] - half, centre[1] + half)
        row = result.summary.iloc[chosen[slot]]
        # a failed instance is said so, not left as an empty panel (an audit, 2026-12)
        failed = "" if row["status"] == "ok" else \
            f": {row['status']} at {row['failure_time_s']:.3g} s, held"
        ax.set_title(f"#{chosen[slot]} {params[slot].gait}{failed}", fontsize=panel_pt,
                     pad=PANEL_TITLE_PAD_PT * panel_pt / PANEL_TITLE_PT)
        drawing.add_scale_bar(ax, drawing.nice_length(2 * half))
        robots.append(drawing.RobotArtist(ax, topology, params[slot].cylinder_diameter * 1e3,
                                          labels=len(chosen) <= 4, path=frame == "world"))
    # the panels below the heading, but on at least half the height (a title of hundreds of
    # characters in a small movie would leave them none)
    _place_panels(fig, max(0.5, min(0.94, heading_bottom - 0.01)), panel_pt, rows)

    def draw(index):
        artists = []
        for slot, robot in enumerate(robots):
            artists += robot.update(shapes[index, slot], hot[slot][index],
                                    None if paths is None else paths[slot][:index + 1])
        label.set_text(_wrapped(heading_at(times[index]), wrap))
        return artists

    movie = animation.FuncAnimation(fig, draw, frames=len(times), blit=False)
    if path.suffix.lower() == ".mp4":
        imageio_ffmpeg = require("imageio_ffmpeg", "video")
        matplotlib.rcParams["animation.ffmpeg_path"] = imageio_ffmpeg.get_ffmpeg_exe()
        writer = animation.FFMpegWriter(fps=fps)
    else:
        writer = animation.PillowWriter(fps=fps)
    # drawn into a scratch folder beside the path, then written whole or not at all: a kill or
    # a full disk leaves a movie already there as it was (ffmpeg reports a full disk by its
    # exit status)
    with _scratch_file(path, (OSError, subprocess.CalledProcessError)) as scratch:
        movie.save(scratch, writer=writer)
        data = scratch.read_bytes()
    write_atomic(path, data, failure=OSError, sidecar=_stale_csv_sidecar(path))
    return path


def _place_panels(figure, top: float, title_pt: float, rows: int):
    """The panels of `figure` (`rows` of them) below `top` (a share of its height) with
    matplotlib's tight layout, or, where their decorations do not fit it (a movie of one or
    two inches: matplotlib warns and leaves the panels over the heading), with fixed margins
    that leave each panel's title of `title_pt` points its line and its gap."""
    before = vars(figure.subplotpars).copy()
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="Tight layout not applied")
        figure.tight_layout(rect=(0, 0, 1, top))
    if vars(figure.subplotpars) != before:
        return
    title_pt *= 1.2 + PANEL_TITLE_PAD_PT / PANEL_TITLE_PT  # a line of text and its gap
    title_share = title_pt * figure.dpi / 72 / figure.bbox.height
    figure.subplots_adjust(left=0.02, right=0.98, bottom=0.02, top=top - title_share,
                           wspace=0.05, hspace=title_share * rows)


def _wrapped(text: str, width: Optional[int]) -> str:
    """`text` with each of its lines wrapped to `width` characters (None: as it is)."""
    if width is None:
        return text
    return "\n".join(textwrap.fill(line, width) for line in text.splitlines())


def _fit_heading(figure, label, longest: str) -> Tuple[Optional[int], float]:
    """Fit `label`, a text of `figure` (the movie's heading), to HEADING_WIDTH_SHARE of the
    figure's width for its longest text `longest`: its font shrunk as far as needed, not below
    HEADING_LEAST_PT, and where that is not enough its lines wrapped to as many characters as
    fit. A heading that fits is left as it is. Leaves `longest` (wrapped) in `label`; returns
    (the wrap width in characters, None for no wrapping; the height of the heading's lowest
    point as a share of the figure's)."""
    renderer = figure.canvas.get_renderer()
    room = HEADING_WIDTH_SHARE * figure.bbox.width
    label.set_text(longest)
    width = label.get_window_extent(renderer).width
    # a text's width is about proportional to its font size; the hinting of small sizes
    # makes it not quite so, hence a few rounds
    while width > room and label.get_fontsize() > HEADING_LEAST_PT:
        label.set_fontsize(max(HEADING_LEAST_PT, label.get_fontsize() * min(0.95, room / width)))
        width = label.get_window_extent(renderer).width
    wrap = None
    while width > room and (wrap is None or wrap > 1):
        characters = max(len(line) for line in label.get_text().splitlines())
        wrap = max(1, min(characters - 1, int(characters * room / width)))
        label.set_text(_wrapped(longest, wrap))
        width = label.get_window_extent(renderer).width
    return wrap, label.get_window_extent(renderer).y0 / figure.bbox.height


def _body_frame(shapes_mm: np.ndarray, topology) -> np.ndarray:
    """Shapes (R, B, N, 2) moved so that the hub is at the origin and the hub-to-joint
    directions keep their rest orientation on average."""
    rest = topology.rest_positions
    joints = topology.joints
    now = shapes_mm[..., joints, :] - shapes_mm[..., CENTRE:CENTRE + 1, :]
    rest_arms = rest[joints] - rest[CENTRE]
    turn = np.arctan2(now[..., 1], now[..., 0]) - np.arctan2(rest_arms[:, 1], rest_arms[:, 0])
    angle = np.arctan2(np.sin(turn).sum(-1), np.cos(turn).sum(-1))
    cos, sin = np.cos(-angle)[..., None], np.sin(-angle)[..., None]
    centred = shapes_mm - shapes_mm[..., CENTRE:CENTRE + 1, :]
    return np.stack([cos * centred[..., 0] - sin * centred[..., 1],
                     sin * centred[..., 0] + cos * centred[..., 1]], axis=-1)

