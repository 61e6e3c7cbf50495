"""Batch fits: every input x every candidate model, on joblib processes or a Dask cluster.

::

    import gonio
    batch = gonio.fit_many(["sample_a.csv", "sample_b.csv", "recordings/"], ["lambert", "oren-nayar"],
                           out="batch", workers=2)
    batch.rows                  # one dict per fit: verdict, chi-square, medians and 95 % intervals, R-hat...
    batch.skipped, batch.failed # task ids resumed from an earlier run, and those that failed

Each (input, model) pair is a task with an id (``INPUT--MODEL``) and a seed derived from
the batch's base seed and that id (:func:`task_seed`), so the numbers depend neither on
the number of workers nor on the order the fits finish. Each fit runs with one BLAS
thread (:func:`gonio.fitting.fit`'s ``blas_threads=1``) and is saved in a folder of its
own under ``out`` (:meth:`gonio.fitting.FitResult.save`, then ``task.json``); a re-run
skips the fits whose folder holds a whole result of the same task and seed, and a fit
that raises records its reason in ``task.json`` and in the table instead of stopping the
batch. The table of every fit is written as ``fits.csv`` and ``fits.nc`` (xarray through
h5netcdf) and summarised in ``overview.md`` (:mod:`gonio.report.batch_overview`).
docs/batch.md describes the command, the columns and Dask use.
"""
from __future__ import annotations

import hashlib
import json
import math
import re
import time
import warnings
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Iterable, Mapping, Sequence

if TYPE_CHECKING:
    from .fitting import Dataset, FitResult

__all__ = ["BatchSettings", "BatchResult", "FitTask", "fit_many", "expand_inputs", "plan_tasks", "task_seed",
           "run_task", "TABLE_COLUMNS", "write_tables"]

#: Files of a batch folder: its settings, the tables, and each task's record (in the task's folder).
BATCH_FILE = "batch.json"
TABLE_CSV = "fits.csv"
TABLE_NETCDF = "fits.nc"
TASK_FILE = "task.json"
BATCH_FORMAT = "gonio-fit-batch"
#: Per-fit columns of the table, before the parameter columns (docs/batch.md).
TABLE_COLUMNS = ("task_id", "input", "model", "status", "seed", "n_data", "quantity", "chi2", "dof", "redchi",
                 "verdict", "converged", "r_hat_max", "ess_bulk_min", "wall_seconds", "failure")
#: Per-parameter statistics: CSV columns ``NAME_STAT``; the netCDF's (task, parameter) variables.
PARAMETER_STATS = ("median", "p2_5", "p97_5", "r_hat", "ess_bulk")
_CSV_STATS = ("median", "p2_5", "p97_5")

Input = Any  # a path, a sequence of paths (one joint fit), a Dataset or a callable returning one


@dataclass(frozen=True)
class BatchSettings:
    """How every fit of a batch loads its data and fits (recorded in ``batch.json``).

    Attributes
    ----------
    mcmc, jitter, n_walkers, max_steps, tau_multiple, rhat_limit, fixed, options, alignment, stray_light
        As :func:`gonio.fitting.fit` (``fixed`` applies to the models that have the parameter).
    quantity, calibration, linearity, columns, angle_unit
        As :func:`gonio.analysis.load_data` (path inputs only).
    """

    mcmc: bool = True
    jitter: bool | str = "auto"
    n_walkers: int | None = None
    max_steps: int = 20000
    tau_multiple: float = 50.0
    rhat_limit: float = 1.01
    fixed: Mapping[str, float] = field(default_factory=dict)
    options: Mapping[str, Any] = field(default_factory=dict)
    alignment: tuple[str, ...] = ()
    stray_light: bool = False
    quantity: str | None = None
    calibration: str = "common"
    linearity: bool = True
    columns: Mapping[str, str] | None = None
    angle_unit: str | None = None

    def to_dict(self) -> dict[str, Any]:
        """JSON form (tuples as lists, mappings as dicts)."""
        return json.loads(json.dumps(asdict(self)))


@dataclass(frozen=True)
class FitTask:
    """One fit of a batch: an input, a model and the seed and folder that follow from them.

    Attributes
    ----------
    task_id : str
        ``INPUT--MODEL`` (file-name safe); names the task's folder.
    input_name : str
        The input's name (a file or folder stem, a mapping key, a dataset label).
    source : object
        What :func:`run_task` loads: path(s), a Dataset, or a callable returning a Dataset
        or ``(Dataset, priors)``.
    model : str
        The model spec, ``NAME`` or ``NAME:p=v,...`` (:func:`gonio.analysis.model_candidates`).
    seed : int
        :func:`task_seed` of the batch's seed and ``task_id``.
    folder : str
        The task's result folder.
    """

    task_id: str
    input_name: str
    source: Any
    model: str
    seed: int
    folder: str

    def describe_input(self) -> str:
        """The input as the table shows it: its path(s), or its name."""
        if isinstance(self.source, (list, tuple)):
            return "+".join(str(p) for p in self.source)
        return str(self.source) if isinstance(self.source, (str, Path)) else self.input_name


@dataclass
class BatchResult:
    """What :func:`fit_many` did.

    Attributes
    ----------
    out : Path
        The batch folder.
    rows : list of dict
        One row per task, in task order (:data:`TABLE_COLUMNS`, then ``parameters``: a
        dict name -> dict of :data:`PARAMETER_STATS`).
    skipped : list of str
        Tasks found finished in ``out`` and not fitted again.
    failed : list of str
        Tasks whose fit raised (their rows give the reason).
    files : dict of str -> Path
        The table and overview files written (``csv``, ``netcdf``, ``overview``).
    """

    out: Path
    rows: list[dict[str, Any]]
    skipped: list[str] = field(default_factory=list)
    failed: list[str] = field(default_factory=list)
    files: dict[str, Path] = field(default_factory=dict)


def task_seed(seed: int, task_id: str) -> int:
    """The seed of one task: a hash of the batch's base seed and the task's id.

    >>> task_seed(0, "plaster--lambert") == task_seed(0, "plaster--lambert") != task_seed(1, "plaster--lambert")
    True
    """
    digest = hashlib.sha256(f"{int(seed)}:{task_id}".encode()).digest()
    return int.from_bytes(digest[:4], "big")


def _slug(text: str) -> str:
    """A file-name safe form of ``text`` (``oren-nayar:ir_weight=1`` -> ``oren-nayar.ir_weight-1``)."""
    return re.sub(r"[^A-Za-z0-9_.+-]", "_", text.replace(":", ".").replace("=", "-").replace(",", "."))


def _is_recording(path: Path) -> bool:
    from .data import RECORDING_FILES

    return (path / RECORDING_FILES[0]).is_file()


def expand_inputs(paths: Iterable[str | Path]) -> dict[str, Path]:
    """The fit inputs under ``paths``, by name: CSV files and recording folders given as
    they are, and the CSV files and recording folders directly inside any other folder.

    Raises
    ------
    FileNotFoundError
        A path does not exist.
    ValueError
        A folder holds no input, or two inputs have the same name (naming both).
    """
    found: dict[str, Path] = {}
    for path in map(Path, paths):
        if not path.exists():
            raise FileNotFoundError(f"{path}: no such file or folder")
        if path.is_dir() and not _is_recording(path):
            members = sorted(p for p in path.iterdir() if p.suffix.lower() == ".csv" and p.is_file()
                             or p.is_dir() and _is_recording(p))
            if not members:
                raise ValueError(f"{path}: holds no CSV file and no recording folder of 'gonio run'")
        else:
            members = [path]
        for member in members:
            name = _slug(member.stem)
            if name in found and found[name] != member:
                raise ValueError(f"inputs {found[name]} and {member} have the same name {name!r}; rename one")
            found[name] = member
    return found


def _named_inputs(inputs: Mapping[str, Input] | Sequence[Input]) -> dict[str, Input]:
    """Inputs by name: a mapping's keys, else path stems (folders expanded) and dataset labels."""
    if isinstance(inputs, Mapping):
        return {_slug(str(k)): v for k, v in inputs.items()}
    named: dict[str, Input] = {}
    for index, item in enumerate([inputs] if isinstance(inputs, (str, Path)) else inputs):
        if isinstance(item, (str, Path)):
            extra = expand_inputs([item])
        elif isinstance(item, (list, tuple)):
            extra = {"+".join(_slug(Path(p).stem) for p in item): tuple(str(p) for p in item)}
        else:
            extra = {_slug(getattr(item, "label", "") or f"input-{index}"): item}
        for name in extra:
            if name in named:
                raise ValueError(f"two inputs have the same name {name!r}; give the inputs as a mapping of names")
        named.update(extra)
    return named


def plan_tasks(inputs: Mapping[str, Input] | Sequence[Input], models: Sequence[str], out: str | Path,
               seed: int = 0) -> list[FitTask]:
    """Every input x every model as :class:`FitTask` (inputs first, in the order given).

    Raises
    ------
    ValueError
        No input, no model, or an unknown model (:func:`gonio.analysis.model_candidates`).
    """
    from .analysis import model_candidates

    named = _named_inputs(inputs)
    specs = list(dict.fromkeys([models] if isinstance(models, str) else models))  # a repeated model once
    model_candidates(specs)  # every spec names a registered model
    if not named:
        raise ValueError("no inputs given: expected CSV files, recording folders or folders holding them")
    tasks = []
    for name, source in named.items():
        for spec in specs:
            task_id = f"{name}--{_slug(spec)}"
            source = str(source) if isinstance(source, Path) else source
            tasks.append(FitTask(task_id, name, source, spec, task_seed(seed, task_id), str(Path(out) / task_id)))
    return tasks


# ---------------------------------------------------------------------- one task
def _load(task: FitTask, settings: BatchSettings) -> tuple[Dataset, dict]:
    """The task's dataset and the priors its data imply."""
    from .analysis import load_data
    from .fitting import Dataset

    source = task.source
    if isinstance(source, Dataset):
        return source, {}
    if callable(source):
        loaded = source()
        return loaded if isinstance(loaded, tuple) else (loaded, {})
    paths = [source] if isinstance(source, (str, Path)) else list(source)
    return load_data(paths, settings.quantity, settings.calibration, settings.linearity,
                     dict(settings.columns) if settings.columns else None, settings.angle_unit)


def _fit(task: FitTask, settings: BatchSettings) -> FitResult:
    """Load and fit one task, with one BLAS thread."""
    from .analysis import model_candidates
    from .fitting import ConvergenceWarning, fit

    dataset, priors = _load(task, settings)
    (name, fixed), = model_candidates([task.model], _fixed_for(task.model, settings.fixed))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)  # the table's converged and r_hat_max say it
        return fit(dataset, name, fixed=fixed, priors=priors, mcmc=settings.mcmc, jitter=settings.jitter,
                   options=dict(settings.options), n_walkers=settings.n_walkers, max_steps=settings.max_steps,
                   tau_multiple=settings.tau_multiple, rhat_limit=settings.rhat_limit, seed=task.seed,
                   alignment=settings.alignment or None, stray_light=settings.stray_light, blas_threads=1)


def _check_fixed(models: str | Sequence[str], fixed: Mapping[str, float]) -> None:
    """Refuse a fixed value that belongs to none of the models (as ``gonio fit --fix``)."""
    from .analysis import model_candidates

    model_candidates([models] if isinstance(models, str) else list(models), fixed)


def _fixed_for(spec: str, fixed: Mapping[str, float]) -> dict[str, float]:
    """The batch's fixed values that belong to the model of ``spec`` (or to every model)."""
    from . import models as registry
    from .fitting.rig_errors import RIG_ERROR_NAMES

    names = set(registry.get(spec.split(":", 1)[0].strip()).param_names) | set(RIG_ERROR_NAMES)
    return {k: v for k, v in fixed.items() if k in names | {"scale", "jitter", "rel_jitter"}}


def _base_row(task: FitTask) -> dict[str, Any]:
    row: dict[str, Any] = {key: None for key in TABLE_COLUMNS}
    row.update(task_id=task.task_id, input=task.describe_input(), model=task.model, seed=task.seed, parameters={})
    return row


def result_row(task: FitTask, result: FitResult, seconds: float) -> dict[str, Any]:
    """The table row of a finished fit (module notes; docs/batch.md, "Columns").

    Without MCMC ``median`` holds the least-squares value and the interval is NaN.
    """
    ls, post = result.least_squares, result.posterior
    row = _base_row(task)
    parameters = {}
    for name in result.free:
        stats = {stat: float(post[stat][name]) if post and name in post.get(stat, {}) else math.nan
                 for stat in PARAMETER_STATS}
        if not post:
            stats["median"] = float(ls.values[name])
        parameters[name] = stats
    row.update(status="ok", n_data=int(result.dataset.n), quantity=result.dataset.quantity, chi2=float(ls.chi2),
               dof=int(ls.dof), redchi=float(ls.redchi),
               verdict=result.adequacy.verdict if result.adequacy is not None else "",
               converged=result.converged, r_hat_max=_extreme(parameters, "r_hat", max),
               ess_bulk_min=_extreme(parameters, "ess_bulk", min), wall_seconds=round(seconds, 3), failure="",
               parameters=parameters, result_id=result.result_id)
    return row


def _extreme(parameters: Mapping[str, Mapping[str, float]], stat: str, pick: Callable) -> float:
    values = [p[stat] for p in parameters.values() if not math.isnan(p[stat])]
    return float(pick(values)) if values else math.nan


def _one_line(error: BaseException) -> str:
    return " ".join(f"{type(error).__name__}: {error}".split())


def run_task(task: FitTask, settings: BatchSettings) -> dict[str, Any]:
    """Fit one task, save it in its folder and return its table row; never raises.

    The result is saved by :meth:`~gonio.fitting.FitResult.save` (``result.json`` last),
    then ``task.json`` records the row; a fit that raises records ``status = "failed"``
    and the reason instead. The BLAS library has one thread throughout (fit and save:
    the saved posterior's log-likelihood draws are matrix work too), so that a worker
    takes one core and its numbers do not depend on the thread count.

    Parameters
    ----------
    task : FitTask
    settings : BatchSettings

    Returns
    -------
    dict
        The table row (:func:`result_row`).
    """
    from threadpoolctl import threadpool_limits

    from .files import write_atomic

    start = time.perf_counter()
    folder = Path(task.folder)
    try:
        _check_task_folder(folder)
        with threadpool_limits(limits=1, user_api="blas"):  # the save's posterior draws too, not the fit alone
            result = _fit(task, settings)
            result.save(folder)
        row = result_row(task, result, time.perf_counter() - start)
    except Exception as error:  # noqa: BLE001 - a failed fit is a row of the table, never the batch's end
        row = _base_row(task)
        row.update(status="failed", failure=_one_line(error), wall_seconds=round(time.perf_counter() - start, 3))
    try:
        folder.mkdir(parents=True, exist_ok=True)
        write_atomic(folder / TASK_FILE, json.dumps(_json_row(row), indent=1, allow_nan=False))
    except OSError as error:
        row.update(status="failed", failure=_one_line(error))
    return row


def _saved_names() -> set[str]:
    """The file names a task folder may hold (FitResult.save's and task.json)."""
    from .fitting.results import CHAIN_FILE, COVARIANCE_FILE, INFERENCE_DATA_FILE, RESULT_FILE, SUMMARY_FILE
    from .fitting.selection import COMPARISON_FILE, COMPARISON_TEXT

    return {RESULT_FILE, CHAIN_FILE, COVARIANCE_FILE, INFERENCE_DATA_FILE, SUMMARY_FILE, COMPARISON_FILE,
            COMPARISON_TEXT, TASK_FILE}


def _check_task_folder(folder: Path) -> None:
    """Refuse a task folder holding files a batch did not write (gonio never overwrites them)."""
    if not folder.exists():
        return
    foreign = sorted(p.name for p in folder.iterdir() if p.name not in _saved_names())
    if foreign:
        raise FileExistsError(f"{folder}: holds files a batch fit did not write ({', '.join(foreign[:3])}); "
                              "move them or choose another output folder")


def _json_row(row: Mapping[str, Any]) -> dict[str, Any]:
    """JSON-safe copy of a row (NaN -> null)."""
    from .fitting.results import _clean

    return _clean(dict(row))


def _row_from_json(data: Mapping[str, Any]) -> dict[str, Any]:
    """A row read back from ``task.json`` (null -> NaN in the numbers)."""
    row = dict(data)
    for key in ("chi2", "redchi", "r_hat_max", "ess_bulk_min"):
        row[key] = math.nan if row.get(key) is None else float(row[key])
    row["parameters"] = {name: {k: math.nan if v is None else float(v) for k, v in stats.items()}
                         for name, stats in (row.get("parameters") or {}).items()}
    return row


def finished_row(task: FitTask) -> dict[str, Any] | None:
    """The row of ``task`` when its folder holds its finished fit, else None.

    Finished: ``task.json`` says ``ok`` for this input, model and seed, and ``result.json``
    carries the result id it names (a whole save of that fit).
    """
    from .fitting.results import RESULT_FILE

    folder = Path(task.folder)
    try:
        record = json.loads((folder / TASK_FILE).read_text(encoding="utf-8"))
        result_id = json.loads((folder / RESULT_FILE).read_text(encoding="utf-8")).get("result_id")
    except (OSError, ValueError):
        return None
    same = all(record.get(k) == v for k, v in
               (("status", "ok"), ("input", task.describe_input()), ("model", task.model), ("seed", task.seed)))
    return _row_from_json(record) if same and result_id and record.get("result_id") == result_id else None


# ---------------------------------------------------------------------- the batch folder
def _open_batch(out: Path, seed: int, settings: BatchSettings) -> None:
    """Create the batch folder, or check that an existing one holds a batch of the same
    settings and seed.

    Raises
    ------
    ValueError
        ``out`` is a file, holds files but no batch, or a batch of other settings (naming
        what differs).
    """
    from .data import experiment_differences
    from .files import write_atomic

    record = {"format": BATCH_FORMAT, "seed": int(seed), "settings": settings.to_dict()}
    path = out / BATCH_FILE
    if out.exists() and not out.is_dir():
        raise ValueError(f"{out}: is a file, expected the batch's output folder")
    if path.is_file():
        stored = json.loads(path.read_text(encoding="utf-8"))
        differences = experiment_differences({k: stored.get(k) for k in record}, record)
        if differences:
            raise ValueError(f"{out}: holds a batch of other settings ({'; '.join(differences)}); resume it with "
                             "the same settings or choose another output folder")
        return
    if out.exists() and any(out.iterdir()):
        raise ValueError(f"{out}: holds files but no fit batch ({BATCH_FILE}); choose a new or empty folder "
                         "(gonio never overwrites files it did not write)")
    out.mkdir(parents=True, exist_ok=True)
    write_atomic(path, json.dumps(record, indent=1))


def fit_many(inputs: Mapping[str, Input] | Sequence[Input] | str | Path, models: str | Sequence[str],
             out: str | Path, *, workers: int = 1, scheduler: Any = None, seed: int = 0,
             settings: BatchSettings | None = None, overview: bool = True,
             progress: Callable[[int, int, Mapping[str, Any]], None] | None = None,
             announce: Callable[[str], None] | None = None) -> BatchResult:
    """Fit every input with every model, in parallel, resumably; write the table.

    Parameters
    ----------
    inputs : path, sequence or mapping
        CSV files and recording folders (a folder that is not a recording stands for the
        CSV files and recordings directly inside it; :func:`expand_inputs`), a tuple of
        paths fitted jointly, :class:`gonio.fitting.Dataset` objects, or callables that
        return a Dataset or ``(Dataset, priors)``; a mapping names them (its keys).
    models : str or sequence of str
        Model specs, ``NAME`` or ``NAME:p=v,...`` (values fixed for that model).
    out : path
        The batch folder: one folder per task, ``batch.json``, ``fits.csv``, ``fits.nc``,
        ``overview.md``. An existing batch folder is resumed (same settings and seed).
    workers : int
        joblib processes (loky); 1 fits in this process.
    scheduler : str or distributed.Client, optional
        Run on a Dask distributed cluster instead: a scheduler address
        (``tcp://host:8786``) or a client. Workers must see the inputs and ``out``.
    seed : int
        The base seed; each task's is :func:`task_seed` of it and the task id.
    settings : BatchSettings, optional
        Data loading and fit options (default: those of :class:`BatchSettings`).
    overview : bool
        Write ``overview.md`` and its chart (:mod:`gonio.report.batch_overview`).
    progress : callable, optional
        ``progress(done, total, row)`` after each fit, and once before them for the fits
        found finished (``row = {"task_id": "N finished earlier", "status": "skipped"}``).
    announce : callable, optional
        Called with a line of text (skipped fits, failures, files written).

    Returns
    -------
    BatchResult

    Raises
    ------
    ValueError, FileNotFoundError
        Bad inputs or models, or an output folder that is not this batch's.

    Examples
    --------
    >>> batch = fit_many(["a.csv", "b.csv"], ["lambert", "minnaert"], out="batch", workers=2)  # doctest: +SKIP
    >>> [row["verdict"] for row in batch.rows]                                                  # doctest: +SKIP
    ['adequate', 'adequate', 'inadequate', 'adequate']
    """
    if workers < 1:
        raise ValueError(f"workers = {workers}: expected at least 1")
    settings = settings or BatchSettings()
    say = announce or (lambda text: None)
    out = Path(out)
    tasks = plan_tasks(inputs, models, out, seed)
    _check_fixed(models, settings.fixed)
    _open_batch(out, seed, settings)
    rows: dict[str, dict[str, Any]] = {}
    for task in tasks:
        row = finished_row(task)
        if row is not None:
            rows[task.task_id] = row
    skipped = list(rows)
    if skipped:
        say(f"skipping {len(skipped)} finished fit(s) found in {out}: {', '.join(skipped[:5])}"
            + (", ..." if len(skipped) > 5 else ""))
    todo = [task for task in tasks if task.task_id not in rows]
    done = len(rows)

    def finished(row: dict[str, Any]) -> None:
        nonlocal done
        rows[row["task_id"]] = row
        done += 1
        if row["status"] != "ok":
            say(f"{row['task_id']}: failed: {row['failure']}")
        if progress is not None:
            progress(done, len(tasks), row)

    if progress is not None and skipped:  # one call for the fits found finished
        progress(done, len(tasks), {"task_id": f"{len(skipped)} finished earlier", "status": "skipped"})
    if scheduler is not None:
        _run_dask(todo, settings, scheduler, finished)
    else:
        _run_joblib(todo, settings, workers, finished)
    ordered = [rows[task.task_id] for task in tasks]
    result = BatchResult(out, ordered, skipped, [r["task_id"] for r in ordered if r["status"] != "ok"])
    result.files = write_tables(ordered, out, {"seed": int(seed), "settings": json.dumps(settings.to_dict())})
    if overview:
        from .report.batch_overview import write_overview

        result.files["overview"] = write_overview(ordered, out)
    return result


def _run_joblib(tasks: Sequence[FitTask], settings: BatchSettings, workers: int,
                finished: Callable[[dict[str, Any]], None]) -> None:
    """Run ``tasks`` on ``workers`` loky processes (in this process for one), as they finish."""
    if not tasks:
        return
    from joblib import Parallel, delayed

    parallel = Parallel(n_jobs=min(workers, len(tasks)), return_as="generator_unordered")
    for row in parallel(delayed(run_task)(task, settings) for task in tasks):
        finished(row)


def _run_dask(tasks: Sequence[FitTask], settings: BatchSettings, scheduler: Any,
              finished: Callable[[dict[str, Any]], None]) -> None:
    """Run ``tasks`` on a Dask distributed cluster (an address or a client), as they finish.

    A task whose worker is lost gets a failure row, as a fit that raises does.
    """
    try:
        from distributed import Client, as_completed
    except ImportError:
        raise ValueError("a Dask scheduler needs dask.distributed: pip install 'gonio[dask]'") from None
    client = scheduler if isinstance(scheduler, Client) else Client(scheduler)
    try:
        futures = {client.submit(run_task, task, settings, pure=False): task for task in tasks}
        for future in as_completed(futures):
            try:
                row = future.result()
            except Exception as error:  # noqa: BLE001 - a lost worker: this task failed, the batch goes on
                row = _base_row(futures[future])
                row.update(status="failed", failure=_one_line(error))
            finished(row)
    finally:
        if client is not scheduler:
            client.close()


# ---------------------------------------------------------------------- tables
def _parameter_names(rows: Sequence[Mapping[str, Any]]) -> list[str]:
    names: list[str] = []
    for row in rows:
        names += [name for name in row.get("parameters", {}) if name not in names]
    return names


def _csv_text(rows: Sequence[Mapping[str, Any]]) -> str:
    """``fits.csv``: :data:`TABLE_COLUMNS`, then ``NAME_median``, ``NAME_p2_5``, ``NAME_p97_5``."""
    import csv
    import io

    names = _parameter_names(rows)
    header = list(TABLE_COLUMNS) + [f"{name}_{stat}" for name in names for stat in _CSV_STATS]
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(header)
    for row in rows:
        cells = [row.get(key) for key in TABLE_COLUMNS]
        cells += [row["parameters"].get(name, {}).get(stat) for name in names for stat in _CSV_STATS]
        writer.writerow(["" if c is None or (isinstance(c, float) and math.isnan(c)) else
                         repr(c) if isinstance(c, float) else c for c in cells])
    return buffer.getvalue()


def _netcdf_bytes(rows: Sequence[Mapping[str, Any]], attributes: Mapping[str, Any]) -> bytes | None:
    """``fits.nc``: the table as an xarray Dataset (dimensions task and parameter), or None
    without xarray."""
    try:
        import xarray as xr
    except ImportError:
        return None
    import numpy as np

    names = _parameter_names(rows)
    variables: dict[str, Any] = {}
    for key in TABLE_COLUMNS[1:]:
        values = [row.get(key) for row in rows]
        if key in ("seed", "n_data", "dof"):
            variables[key] = ("task", np.array([-1 if v is None else v for v in values], np.int64))
        elif key in ("chi2", "redchi", "r_hat_max", "ess_bulk_min", "wall_seconds"):
            variables[key] = ("task", np.array([math.nan if v is None else v for v in values], float))
        else:
            variables[key] = ("task", np.array(["" if v is None else str(v) for v in values], dtype=str))
    for stat in PARAMETER_STATS:
        variables[stat] = (("task", "parameter"), np.array(
            [[row["parameters"].get(name, {}).get(stat, math.nan) for name in names] for row in rows], float))
    data = xr.Dataset(variables, coords={"task": [row["task_id"] for row in rows], "parameter": names},
                      attrs={"format": BATCH_FORMAT, **attributes})
    return bytes(data.to_netcdf(engine="h5netcdf"))


def write_tables(rows: Sequence[Mapping[str, Any]], out: str | Path,
                 attributes: Mapping[str, Any] | None = None) -> dict[str, Path]:
    """Write ``fits.csv`` and, with xarray, ``fits.nc`` into ``out``; return their paths.

    Parameters
    ----------
    rows : sequence of dict
        :attr:`BatchResult.rows`.
    out : path
        The batch folder.
    attributes : mapping, optional
        Global attributes of the netCDF file (the base seed, the settings).
    """
    from .files import write_atomic

    out = Path(out)
    files = {"csv": write_atomic(out / TABLE_CSV, _csv_text(rows))}
    netcdf = _netcdf_bytes(rows, dict(attributes or {}))
    if netcdf is not None:
        files["netcdf"] = write_atomic(out / TABLE_NETCDF, netcdf)
    return files
