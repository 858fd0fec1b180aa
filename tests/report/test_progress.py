"""Per-job logs and progress: records go to the job's log file; bars and echoes only on a terminal."""
from __future__ import annotations

import io
import logging
import subprocess
import sys
import textwrap

import pytest

from tissuemech.pipeline import job_log, progress


class _Terminal(io.StringIO):
    def isatty(self):
        return True


def test_batch_job_logs_to_file_only(tmp_path, monkeypatch):
    terminal = io.StringIO()  # not a tty: a batch/cluster job
    monkeypatch.setattr(sys, "__stderr__", terminal)
    log_file = tmp_path / "logs" / "demo" / "fit.log"
    with job_log(log_file) as log:
        total = sum(progress(range(5), "fitting models"))
        log.info("ranked %d models", 5)
        print("solver chatter", file=sys.stderr)
    text = log_file.read_text()
    assert total == 10
    assert "fitting models: 5 items" in text and "fitting models: 5 items in" in text
    assert "ranked 5 models" in text and "solver chatter" in text
    assert terminal.getvalue() == ""


def test_interactive_job_shows_bar_and_echo_on_terminal(tmp_path, monkeypatch):
    terminal = _Terminal()
    monkeypatch.setattr(sys, "__stderr__", terminal)
    log_file = tmp_path / "logs" / "demo" / "fem.log"
    with job_log(log_file) as log:
        list(progress(["a", "b", "c"], "torsion cards"))
        logging.getLogger("numba.core").info("library noise")
        log.info("done")
    shown = terminal.getvalue()
    assert "\rtorsion cards:   0%" in shown and "0/3" in shown  # the tqdm bar (cleared when done)
    assert f"[{(tmp_path / 'logs' / 'demo' / 'fem').as_posix()}] done" in shown
    assert "library noise" not in shown and "library noise" in log_file.read_text()


def test_failed_job_leaves_its_traceback_in_the_log(tmp_path):
    log_file = tmp_path / "job.log"
    with pytest.raises(ValueError, match="bad curve"):
        with job_log(log_file):
            raise ValueError("bad curve")
    text = log_file.read_text()
    assert "job failed" in text and "ValueError: bad curve" in text


def test_job_log_ends_with_the_jobs_cpu_seconds_and_memory(tmp_path):
    import re
    import time

    log_file = tmp_path / "job.log"
    with job_log(log_file):
        end = time.process_time() + 0.3
        while time.process_time() < end:      # burn 0.3 CPU s
            pass
    match = re.search(r"job cost: cpu_s=([0-9.]+) children_cpu_s=([0-9.]+) max_rss_mb=([0-9]+)", log_file.read_text())
    assert match, log_file.read_text()
    assert float(match.group(1)) >= 0.3 and int(match.group(3)) > 10


def _run_job_script(tmp_path, body: str):
    script = tmp_path / "job.py"
    script.write_text(textwrap.dedent(f"""
        import atexit, sys
        from tissuemech.pipeline import job_log
        atexit.register(lambda: open({str(tmp_path / 'teardown')!r}, "w").close())
        print("stdout before the job")
        with job_log({str(tmp_path / 'job.log')!r}, end_process=True) as log:
            log.info("job body")
            print("stdout in the job")
        {body}
        open({str(tmp_path / 'after')!r}, "w").close()
        """))
    return subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=120)


def test_a_finished_script_job_ends_its_process_without_teardown(tmp_path):
    done = _run_job_script(tmp_path, "")
    assert done.returncode == 0, done.stderr
    text = (tmp_path / "job.log").read_text()
    assert "job body" in text and "job cost: cpu_s=" in text
    assert done.stdout.splitlines() == ["stdout before the job", "stdout in the job"]  # flushed, not lost
    assert not (tmp_path / "after").exists()       # nothing after the job block runs
    assert not (tmp_path / "teardown").exists()    # nor the interpreter's exit handlers


def test_a_failed_script_job_still_fails_with_its_traceback(tmp_path):
    script = tmp_path / "job.py"
    script.write_text(textwrap.dedent(f"""
        from tissuemech.pipeline import job_log
        with job_log({str(tmp_path / 'job.log')!r}, end_process=True):
            raise ValueError("bad sample sheet")
        """))
    done = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=120)
    assert done.returncode == 1
    assert "ValueError: bad sample sheet" in done.stderr
    text = (tmp_path / "job.log").read_text()
    assert "job failed" in text and "ValueError: bad sample sheet" in text and "job cost" in text
