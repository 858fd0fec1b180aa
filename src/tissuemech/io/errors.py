"""The one exception type of ingest: it always names the file, and the line/column when known."""
from __future__ import annotations

from pathlib import Path


class IngestError(ValueError):
    """A problem in an input file (or sample sheet row).

    Parameters
    ----------
    path : the offending file
    problem : what is wrong, in words
    line : 1-based line number (text files) or row number (spreadsheets), when known
    column : column label or 1-based index, when known
    """

    def __init__(self, path, problem: str, line: int | None = None, column: str | int | None = None):
        self.path = Path(path)
        self.problem = problem
        self.line = line
        self.column = column
        where = str(self.path)
        if line is not None:
            where += f", line {line}"
        if column is not None:
            where += f", column {column!r}" if isinstance(column, str) else f", column {column}"
        super().__init__(f"{where}: {problem}")
