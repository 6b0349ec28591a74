"""One exception type for problems a user can fix (bad input, unwritable output).

The CLI turns a RanadError into a one-line message and exit code 2; anything else is an internal error
(exit code 1). Keeping the file name in the exception lets every layer raise without knowing how it is shown.
A problem that arrives with several lines (a library's message wrapped into ours) is joined into one, so the
CLI's ``ranad: error: <file>: <problem>`` stays a single line whatever the cause.
"""

from __future__ import annotations

import os


class RanadError(Exception):
    """A user-facing error about one file (or none): ``str(e)`` is ``"<path>: <problem>"``, one line."""

    def __init__(self, problem: str, path: str | os.PathLike | None = None):
        problem = str(problem)
        if "\n" in problem or "\r" in problem:
            problem = " ".join(line.strip() for line in problem.splitlines() if line.strip())
        self.problem = problem
        self.path = None if path is None else os.fspath(path)
        super().__init__(f"{self.path}: {problem}" if self.path else problem)
