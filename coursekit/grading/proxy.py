"""What the graded tests hold instead of the student's objects: proxies that forward to a worker.

See :mod:`coursekit.grading.remote` for the worker behind them.
"""

from __future__ import annotations

from typing import Any


class StudentCodeError(AssertionError):
    """The student's code raised, or the worker running it failed; ``cause`` says which.

    ``cause``: "error" (an exception, ``kind`` is its type), "import" (the module failed to import),
    "timeout", "crashed" (the process ended), "memory", "output" (printed too much),
    "reference" (called the reference implementation / imported solutions), "protocol".
    """

    def __init__(self, cause: str, kind: str, message: str, traceback: str = "") -> None:
        super().__init__(message)
        self.cause, self.kind, self.message, self.traceback = cause, kind, message, traceback

    @property
    def report(self) -> str:
        """One line: "ValueError: bad shape", "Timeout (>1s): ...", "calls the reference implementation (...)"."""
        return f"{self.kind}: {self.message}" if self.kind else self.message


class RemoteObject:
    """A handle to an object living in the worker: call it, read attributes, pass it back in."""

    def __init__(self, box: Any, generation: int, oid: int, type_name: str) -> None:
        object.__setattr__(self, "_box", box)
        object.__setattr__(self, "_gen", generation)
        object.__setattr__(self, "_id", oid)
        object.__setattr__(self, "type_name", type_name)

    def __call__(self, *args, **kwargs):
        return self._box.request("call", target=self, args=list(args), kwargs=kwargs)

    def __getattr__(self, name: str):
        if name.startswith("__"):
            raise AttributeError(name)
        return self._box.request("getattr", target=self, name=name)

    def __setattr__(self, name, value):
        raise AttributeError("objects in the worker are read-only from the tests (use sandbox.load_state_dict)")

    def __repr__(self) -> str:
        return f"<remote {self.type_name} #{self._id}>"


class RemoteAttr:
    """A name in the student's module (resolved in the worker each time it is used)."""

    def __init__(self, box: Any, name: str) -> None:
        self._box, self.name = box, name

    def __call__(self, *args, **kwargs):
        return self._box.request("call", target=self, args=list(args), kwargs=kwargs)

    def __repr__(self) -> str:
        return f"<student's {self.name}>"


class RemoteModule:
    """The student's module as the tests see it: ``student.<name>(...)`` runs in the worker."""

    def __init__(self, box: Any) -> None:
        self._box = box

    def __getattr__(self, name: str) -> RemoteAttr:
        if name.startswith("_"):
            raise AttributeError(name)
        return RemoteAttr(self._box, name)
