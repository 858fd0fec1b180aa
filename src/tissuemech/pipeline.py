"""Small helpers shared by the Snakemake adapter scripts (``workflow/scripts``): logging and run loading."""
from __future__ import annotations

import logging
import sys
from contextlib import contextmanager
from pathlib import Path

import xarray as xr

from .canonical import read_netcdf


@contextmanager
def job_log(log_path: str | Path):
    """Send warnings, ``logging`` records and stderr of a job to its Snakemake log file.

    Uncaught exceptions are written to the log with their traceback before they propagate, so
    ``--show-failed-logs`` shows the cause.
    """
    log_path = Path(log_path)
    log_path.parent.mkdir(parents=True, exist_ok=True)
    with open(log_path, "w", encoding="utf-8") as fh:
        handler = logging.StreamHandler(fh)
        handler.setFormatter(logging.Formatter("%(asctime)s %(levelname)s %(name)s: %(message)s"))
        root = logging.getLogger()
        root.addHandler(handler)
        root.setLevel(logging.INFO)
        logging.captureWarnings(True)
        old_stderr = sys.stderr
        sys.stderr = fh
        try:
            yield logging.getLogger("tissuemech")
        except BaseException:
            logging.getLogger("tissuemech").exception("job failed")
            raise
        finally:
            sys.stderr = old_stderr
            root.removeHandler(handler)
            logging.captureWarnings(False)


def load_runs(runs_dir: str | Path) -> list[xr.Dataset]:
    """Every canonical run file ``runs_dir/*.nc`` fully loaded, sorted by file name."""
    return [read_netcdf(path) for path in sorted(Path(runs_dir).glob("*.nc"))]
