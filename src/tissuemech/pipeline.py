"""Small helpers shared by the Snakemake adapter scripts (``workflow/scripts``): logging, progress, run loading, and
the workflow's plan of one dataset read from its sample sheet (which stages run, which scope the diagnosis reads),
shared by ``workflow/rules/common.smk`` and :func:`tissuemech.analysis.analyse_dataset`."""
from __future__ import annotations

import logging
import os
import resource
import sys
import time
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import NoReturn, TypeVar

import pandas as pd
import xarray as xr

from .canonical import read_netcdf
from .curves import distinct_temperatures


def job_cost() -> str:
    """CPU seconds (user + system) of this process since it started -- imports included -- and of its finished
    children, and its peak resident memory: exact figures, where Snakemake's ``benchmark`` samples (issue 17)."""
    own = resource.getrusage(resource.RUSAGE_SELF)
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (f"cpu_s={own.ru_utime + own.ru_stime:.2f} children_cpu_s={children.ru_utime + children.ru_stime:.2f} "
            f"max_rss_mb={own.ru_maxrss / 1024:.0f}")


@contextmanager
def job_log(log_path: str | Path, *, end_process: bool = False):
    """Send warnings, ``logging`` records and stderr of a job to its Snakemake log file.

    Uncaught exceptions are written to the log with their traceback before they propagate, so
    ``--show-failed-logs`` shows the cause. When the job runs interactively (the process's original stderr
    is a terminal) the records are also echoed there, prefixed with the log's name, so a long job shows
    what it is doing; :func:`progress` bars go to the terminal too.

    Parameters
    ----------
    log_path : the job's log file.
    end_process : for a process that is the job and nothing else (a ``workflow/scripts`` adapter, whose last
        statement is this ``with`` block): when the job succeeds, flush and close the log and the standard
        streams and end the process with exit status 0 (:func:`end_job_process`) instead of returning. A
        failed job propagates its exception as usual.
    """
    log_path = Path(log_path)
    log_path.parent.mkdir(parents=True, exist_ok=True)
    with open(log_path, "w", encoding="utf-8") as fh:
        handler = logging.StreamHandler(fh)
        handler.setFormatter(logging.Formatter("%(asctime)s %(levelname)s %(name)s: %(message)s"))
        root = logging.getLogger()
        root.addHandler(handler)
        echo = None
        if _interactive():
            echo = logging.StreamHandler(sys.__stderr__)
            echo.setLevel(logging.INFO)
            echo.addFilter(logging.Filter("tissuemech"))  # the package's own records, not every library's
            echo.setFormatter(logging.Formatter(f"[{log_path.with_suffix('').as_posix()}] %(message)s"))
            root.addHandler(echo)
        root.setLevel(logging.INFO)
        package = logging.getLogger("tissuemech")
        # a job's records must reach its log whatever an earlier caller in the process set (e.g. a quiet CLI)
        old_level = package.level
        package.setLevel(logging.NOTSET)
        logging.captureWarnings(True)
        old_stderr = sys.stderr
        sys.stderr = fh
        succeeded = False
        try:
            yield package
            succeeded = True
        except BaseException:
            package.exception("job failed")
            raise
        finally:
            package.info("job cost: %s", job_cost())
            package.setLevel(old_level)
            sys.stderr = old_stderr
            root.removeHandler(handler)
            if echo is not None:
                root.removeHandler(echo)
            logging.captureWarnings(False)
    if succeeded and end_process:
        end_job_process()


def end_job_process() -> NoReturn:
    """End this process with exit status 0 without the interpreter's teardown.

    Teardown (module finalisation and freeing every object of scipy, pandas, matplotlib, lmfit, numba, ...)
    costs ~0.4 CPU s per process with the package imported, about 30 of the pipeline's ~400 job CPU seconds
    over its 78 jobs (issue 17). Only for a finished job process: every output was written and closed
    (atomically, :func:`tissuemech.canonical.atomic_write`) before this; ``atexit`` handlers do not run, the
    ``logging`` handlers and the standard streams are flushed first.
    """
    logging.shutdown()
    for stream in (sys.stdout, sys.stderr, sys.__stdout__, sys.__stderr__):
        if stream is not None:
            stream.flush()
    os._exit(0)


def _interactive() -> bool:
    """True when the process's original stderr is a terminal (an interactive ``snakemake`` run)."""
    stream = sys.__stderr__
    return bool(stream is not None and hasattr(stream, "isatty") and stream.isatty())


_Item = TypeVar("_Item")


def progress(items: Iterable[_Item], desc: str, total: int | None = None,
             logger: logging.Logger | None = None) -> Iterator[_Item]:
    """Iterate ``items`` with a tqdm bar on the terminal (interactive runs only) and start/end lines in the log.

    Inside :func:`job_log` ``sys.stderr`` is the job's log file, so the bar is drawn on the process's original
    stderr and is disabled when that is not a terminal (batch or cluster jobs keep clean logs).
    """
    from tqdm import tqdm

    log = logger or logging.getLogger("tissuemech")
    if total is None and hasattr(items, "__len__"):
        total = len(items)  # type: ignore[arg-type]
    log.info("%s: %s items", desc, "?" if total is None else total)
    start, done = time.perf_counter(), 0
    bar = tqdm(items, desc=desc, total=total, file=sys.__stderr__, disable=not _interactive(), leave=False,
               dynamic_ncols=True)
    for item in bar:
        yield item
        done += 1
    log.info("%s: %d items in %.1f s", desc, done, time.perf_counter() - start)


def load_runs(runs_dir: str | Path) -> list[xr.Dataset]:
    """Every canonical run file ``runs_dir/*.nc`` fully loaded, sorted by file name."""
    return [read_netcdf(path) for path in sorted(Path(runs_dir).glob("*.nc"))]


# ---- the plan of one dataset (the DAG's decisions, made from the sample sheet before any run is read) ----------
#: scopes whose fits the diagnosis examines, best first (the joint viscoelastic fit carries most evidence): the
#: diagnosis reads the fit records of the first of these a dataset has
DIAGNOSIS_SCOPES: tuple[str, ...] = (
    "material", "all_modes", "constant_shear_rate", "stress_relaxation", "creep_recovery",
    "frequency_sweep", "mastercurve", "amplitude_sweep", "simple_shear", "flow_curve",
)
#: test kinds of homogeneous specimens (not parallel-plate data)
HOMOGENEOUS_TESTS = frozenset({"simple_shear", "uniaxial", "indentation"})


def sheet_tests(sheet) -> list[str]:
    """Test kinds of a sample sheet (a ``pandas.DataFrame`` read with ``dtype=str``), sorted."""
    return sorted(set(sheet["test"].dropna())) if "test" in sheet else []


def sweep_temperatures(sheet) -> list[float]:
    """Distinct nominal temperatures (column ``temperature_c``) of a sample sheet's frequency sweeps
    (:func:`tissuemech.curves.distinct_temperatures`); two or more give the dataset the TTS stage and the
    ``mastercurve`` scope."""
    if "test" not in sheet or "temperature_c" not in sheet:
        return []
    sweeps = sheet[sheet["test"] == "frequency_sweep"]
    values = sweeps["temperature_c"].astype("string")
    if sheet.attrs.get("decimal_comma"):  # a sheet of tissuemech.io.samples.read_sheet written with 20,5
        values = values.str.replace(",", ".", regex=False)
    return distinct_temperatures(pd.to_numeric(values, errors="coerce"))


def diagnosis_scope(scopes: Iterable[str]) -> str | None:
    """The scope whose fits the diagnosis reads: the first of :data:`DIAGNOSIS_SCOPES` among ``scopes``."""
    scopes = set(scopes)
    return next((s for s in DIAGNOSIS_SCOPES if s in scopes), None)


def is_rheometer_dataset(tests: Iterable[str]) -> bool:
    """Parallel-plate data (the plate-level diagnosis applies) as opposed to homogeneous specimens."""
    return bool(set(tests) - HOMOGENEOUS_TESTS)


def is_multimode_dataset(tests: Iterable[str]) -> bool:
    """Homogeneous specimens tested in simple shear and uniaxially (the cross-mode diagnosis applies)."""
    return {"simple_shear", "uniaxial"} <= set(tests)


def is_diagnosed(tests: Iterable[str], scopes: Iterable[str]) -> bool:
    """Whether the workflow diagnoses a dataset: it has a diagnosis scope and is rheometer or multi-mode data."""
    tests = list(tests)
    return diagnosis_scope(scopes) is not None and (is_rheometer_dataset(tests) or is_multimode_dataset(tests))
