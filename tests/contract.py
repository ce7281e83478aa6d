"""The error contract of every user-facing entry point (issue 12), as a check
that property-based tests run on each generated input, and the tally of what
the generators produced (printed at the end of a pytest run, see conftest.py).

The contract: an input is either accepted, or refused with an
:class:`~lpvest.core._errors.LpvestError` of the expected subclass whose message is
one line of at most :data:`~lpvest.core._errors.MESSAGE_LIMIT` characters, starts
with the name of the file (or formula) and leaks no internal name; nothing
takes more than :data:`CPU_LIMIT` seconds of CPU time. Anything else (another
exception, a bad message, a timeout) fails the test and is counted.
"""

from __future__ import annotations

import faulthandler
import gc
import signal
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from lpvest.core._errors import MESSAGE_LIMIT, LpvestError

#: CPU seconds one example may take: the CPU time of the thread that runs it
#: (``time.thread_time``), so that neither another job on the machine nor another
#: thread of the test process (a Dask client's, an FMU's, left by an earlier
#: test file in the same process) counts against it. A malformed input must be
#: refused at once.
CPU_LIMIT = 1.0
#: A process-wide CPU timer (``ITIMER_PROF``, every thread) at this multiple of the
#: limit stops an example that would never return; one that returns is judged by
#: its own thread's CPU time against the limit.
BACKSTOP = 10
#: Wall-clock seconds after which a hang inside C code (where the CPU timer's
#: signal cannot interrupt) ends the test process with a traceback.
HANG_LIMIT = 120

#: Text that must never reach a user: internal names and Python internals.
LEAKS = ("__shift__", "<lpvest formula", " object at 0x", "Traceback", "<module>", "<lambda>")


@dataclass
class Tally:
    """What one generator's inputs did."""

    accepted: int = 0
    typed: int = 0  #: refused with the expected error and a good message
    bad_message: int = 0  #: refused with the expected error type but a message breaking the contract
    other: int = 0  #: any other exception (the contract broken)
    timeouts: int = 0
    slowest: float = 0.0  #: CPU seconds of the slowest example

    @property
    def total(self) -> int:
        return self.accepted + self.typed + self.bad_message + self.other + self.timeouts

    def line(self, name: str) -> str:
        return (f"{name:<22} {self.total:>6} examples: accepted {self.accepted}, typed error {self.typed}, "
                f"other {self.other + self.bad_message}, timeouts {self.timeouts} "
                f"(slowest {1e3 * self.slowest:.0f} ms CPU)")


#: Tallies by generator name, filled as the property tests run.
TALLIES: dict[str, Tally] = {}


class ContractTimeout(BaseException):
    """An example ran out of CPU time (a BaseException, so that no
    ``except Exception`` in the code under test swallows it)."""


def _on_timer(signum: int, frame: object) -> None:
    raise ContractTimeout()


def check_message(message: str, prefix: str, given: str | bytes = "", paths: Sequence[str] = ()) -> list[str]:
    """What is wrong with an error message (empty: nothing). ``given`` is the
    input: what the user wrote may be quoted, even if it looks internal.
    ``paths`` are folders of the test (pytest's temporary folders): the length
    bound is measured on the message without them, so that it does not depend
    on how long pytest's temporary path happens to be."""
    problems = []
    if len(message.splitlines()) > 1 or message.endswith(("\n", "\r")):
        problems.append("more than one line")
    measured = message
    for path in sorted(paths, key=len, reverse=True):
        measured = measured.replace(path, "")
    if len(measured) > MESSAGE_LIMIT:
        problems.append(f"{len(measured)} characters without the test's folders (more than {MESSAGE_LIMIT})")
    if not message.startswith(prefix):
        problems.append(f"does not start with {prefix!r}")
    elif not message[len(prefix):].strip():
        problems.append("says nothing after the name")
    shown = given.decode("utf-8", "replace") if isinstance(given, bytes) else given
    problems += [f"leaks {leak!r}" for leak in LEAKS if leak in message and leak not in shown]
    return problems


def within_contract(
    generator: str,
    action: Callable[[], object],
    *,
    prefix: str,
    error: type[LpvestError] = LpvestError,
    given: str | bytes = "",
    refused: Callable[[object], bool] | None = None,
    limit: float = CPU_LIMIT,
    paths: Sequence[str] = (),
) -> str | None:
    """Run ``action`` under the contract; return the error message (``None``
    when the input was accepted). Raises ``AssertionError`` when the contract
    is broken; counts the outcome in :data:`TALLIES`. ``refused`` tells from
    the action's result that the input was refused without an exception (a
    command line's exit status 2); ``paths`` as for :func:`check_message`."""
    tally = TALLIES.setdefault(generator, Tally())
    # no garbage collection inside the timed call: a collection of the test
    # runner's garbage would count against the input (and the timer's
    # exception, raised inside a gc callback, would be ignored)
    gc_was_enabled = gc.isenabled()
    gc.disable()
    previous = signal.signal(signal.SIGPROF, _on_timer)
    signal.setitimer(signal.ITIMER_PROF, BACKSTOP * limit)
    faulthandler.dump_traceback_later(HANG_LIMIT, exit=True)
    start = time.thread_time()

    def timed() -> object:
        try:
            return action()
        finally:  # over the limit is a timeout, whatever the outcome
            if time.thread_time() - start > limit and not isinstance(sys.exc_info()[1], ContractTimeout):
                raise ContractTimeout()

    try:
        result = timed()
    except ContractTimeout:
        tally.timeouts += 1
        raise AssertionError(f"{generator}: the input took more than {limit} s of CPU time") from None
    except error as exc:
        message = str(exc)
        problems = check_message(message, prefix, given, paths)
        if problems:
            tally.bad_message += 1
            raise AssertionError(f"{generator}: {type(exc).__name__} message {message!r}: "
                                 + "; ".join(problems)) from exc
        tally.typed += 1
        return message
    except BaseException:
        tally.other += 1
        raise
    else:
        if refused is not None and refused(result):
            tally.typed += 1
        else:
            tally.accepted += 1
        return None
    finally:
        signal.setitimer(signal.ITIMER_PROF, 0)
        signal.signal(signal.SIGPROF, previous)
        if gc_was_enabled:
            gc.enable()
        faulthandler.cancel_dump_traceback_later()
        tally.slowest = max(tally.slowest, time.thread_time() - start)


def report() -> list[str]:
    """The tally of every generator that ran, one line each, and the total."""
    if not TALLIES:
        return []
    lines = [t.line(name) for name, t in sorted(TALLIES.items())]
    total = Tally()
    for t in TALLIES.values():
        total.accepted += t.accepted
        total.typed += t.typed
        total.bad_message += t.bad_message
        total.other += t.other
        total.timeouts += t.timeouts
        total.slowest = max(total.slowest, t.slowest)
    return [*lines, total.line("all generators")]
