"""Interruption of long calls: ``Ctrl-C`` (SIGINT) and SIGTERM.

Three things keep a signal from being lost on its way to the code that acts
on it:

- :func:`handling_signals` makes both signals raise :class:`Interrupted` (a
  ``KeyboardInterrupt`` carrying the signal number, hence the exit status
  130 or 143) in the main thread, and records the signal as *pending*: code
  that sees a failure a signal caused (an FMU's ``doStep`` returning fatal
  because pythonfmu caught the ``KeyboardInterrupt`` raised inside it) asks
  :func:`raise_if_pending` before blaming anyone.
- :func:`call_interruptibly` runs a native call that does not look at Python's
  signals (an LMI solver: Clarabel finishes its solve before Python's handler
  runs) on a worker thread while the main thread waits, where the handler
  runs at once. An interrupted call is abandoned: its thread runs on, its
  result is dropped, and the caller must not reuse what the thread still
  writes to (the H-infinity program is dropped from its cache).
- SCS installs its own SIGINT handler while it solves and returns "interrupted"
  instead: :mod:`lpvest.design` turns that status into
  :class:`Interrupted`.

Test hook (documented for the interruption tests, harmless otherwise): with
``LPVEST_TEST_HOLD=MOMENT`` and ``LPVEST_TEST_READY=FILE`` in the
environment, :func:`hold` at that moment appends ``MOMENT`` and a newline to
``FILE`` and then waits for a signal (forever, on a thread other than the main
one). A test starts the command, waits for the line (an event, not a delay),
sends the signal and checks what the command did. Moments: ``solve`` (an LMI
solve has started, on its worker thread), ``fmu-step`` (inside an lpvest FMU's
``fmi2DoStep``), ``sweep-outcome`` (a sweep has written its first finished
task), ``sweep-finish`` (every task is written; figures are next),
``experiment-written`` (``lpvest reproduce`` has written an experiment's
``results.json`` and resume record; the next one, or the report, follows),
``reference-part`` (``lpvest regress --update`` has written a reference
beside its file; renaming it into place follows), ``reference-written``
(a reference file is in place; the next reference follows).
"""

from __future__ import annotations

import contextlib
import functools
import os
import signal
import threading
from collections.abc import Callable, Iterator
from typing import TYPE_CHECKING, Any, ParamSpec, TypeVar, cast

if TYPE_CHECKING:
    from types import FrameType

__all__ = ["Interrupted", "handling_signals", "raise_if_pending", "call_interruptibly", "hold", "holds",
           "interruptible", "exit_status", "abandoned_calls"]

T = TypeVar("T")

_NAMES: dict[int, str] = {int(signal.SIGINT): "SIGINT", int(signal.SIGTERM): "SIGTERM"}


class Interrupted(KeyboardInterrupt):
    """A signal (SIGINT or SIGTERM) stopped a long call.

    Parameters
    ----------
    signum : int
        The signal; the command line exits with ``128 + signum`` (130, 143).
    """

    def __init__(self, signum: int = signal.SIGINT) -> None:
        super().__init__(_NAMES.get(signum, f"signal {signum}"))
        self.signum = int(signum)

    @property
    def name(self) -> str:
        return _NAMES.get(self.signum, f"signal {self.signum}")


def exit_status(exc: BaseException) -> int:
    """130 for SIGINT (and a plain ``KeyboardInterrupt``), 143 for SIGTERM.

    Parameters
    ----------
    exc : BaseException
        The exception that stopped the command; its ``signum`` attribute (as
        on :class:`Interrupted`) names the signal, SIGINT when it has none.

    Returns
    -------
    int
        ``128 + signum``, the exit status of a process the signal ended.
    """
    return 128 + getattr(exc, "signum", signal.SIGINT)


_pending: int | None = None
_depth = 0
_deferring = 0  # > 0: the handler records the signal in _deferred instead of raising
_deferred: int | None = None


def _handler(signum: int, frame: FrameType | None) -> None:
    global _pending, _deferred
    _pending = signum
    if _deferring:
        _deferred = signum
        return
    raise Interrupted(signum)


@contextlib.contextmanager
def _signals_deferred() -> Iterator[None]:
    """Within this context :func:`_handler` records a signal and raises its
    :class:`Interrupted` when the context ends: a few statements that must
    not be cut in two (a thread started and recorded as started)."""
    global _deferring, _deferred
    _deferring += 1
    signum = None
    try:
        yield
    finally:
        _deferring -= 1
        if _deferring == 0:
            signum, _deferred = _deferred, None
    if signum is not None:
        raise Interrupted(signum)


def raise_if_pending() -> None:
    """Raise :class:`Interrupted` if a signal arrived within
    :func:`handling_signals` (and something swallowed its exception)."""
    if _pending is not None:
        raise Interrupted(_pending)


@contextlib.contextmanager
def handling_signals() -> Iterator[None]:
    """SIGINT and SIGTERM raise :class:`Interrupted` within this context (in the
    main thread; elsewhere, and where the program installed its own handlers,
    nothing changes). Nested uses share the outermost one's state."""
    global _depth, _pending
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous: dict[int, Any] = {}
    for signum, default in ((signal.SIGINT, signal.default_int_handler), (signal.SIGTERM, signal.SIG_DFL)):
        current = signal.getsignal(signum)
        if current is default or current is _handler:
            previous[signum] = current
            signal.signal(signum, _handler)
    if _depth == 0:
        _pending = None
    _depth += 1
    try:
        yield
    finally:
        _depth -= 1
        for number, handler in previous.items():
            signal.signal(number, handler)


P = ParamSpec("P")
R = TypeVar("R")


def interruptible(fn: Callable[P, R]) -> Callable[P, R]:
    """Decorator: ``fn`` runs within :func:`handling_signals`.

    Parameters
    ----------
    fn : callable
        The function to wrap.

    Returns
    -------
    callable
        A wrapper with ``fn``'s signature and metadata (:func:`functools.wraps`)
        that calls ``fn`` within :func:`handling_signals` and returns its result.
    """

    @functools.wraps(fn)
    def wrapper(*args: P.args, **kwargs: P.kwargs) -> R:
        with handling_signals():
            return fn(*args, **kwargs)

    return wrapper


class _Call:
    """``fn()`` on a daemon thread; :attr:`finished` is set once it has ended.

    Its end is this event, not the thread's ``join``/``is_alive``: on CPython
    3.11 a ``join`` that a signal's exception interrupts marks the thread as
    stopped although it runs on (``Thread._wait_for_tstate_lock``'s clean-up
    for bpo-45274 releases the lock the running thread holds), so an
    abandoned solve looked finished: the command then left through the
    interpreter's shutdown with the solver still running, which now and then
    aborted it ("terminate called without an active exception", SIGABRT).
    """

    def __init__(self, fn: Callable[[], Any]) -> None:
        self._fn = fn
        self.value: Any = None
        self.error: BaseException | None = None
        self.finished = threading.Event()
        self.thread = threading.Thread(target=self._run, name="lpvest-solve", daemon=True)

    def _run(self) -> None:
        try:
            self.value = self._fn()
        except BaseException as exc:  # noqa: BLE001 - handed to the waiting thread
            self.error = exc
        finally:
            self.finished.set()

    def running(self) -> bool:
        """Started and not yet ended."""
        return self.thread.ident is not None and not self.finished.is_set()


def call_interruptibly(fn: Callable[[], T], *, on_abandon: Callable[[threading.Event], None] | None = None) -> T:
    """``fn()`` on a worker thread while this (main) thread waits, so that a
    signal's handler runs at once; on another thread, ``fn()`` directly.
    Runs within :func:`handling_signals`.

    Parameters
    ----------
    fn : callable
        The call, without arguments.
    on_abandon : callable or None, optional
        Called, when a signal abandons the call, with an event that is set
        once the abandoned call has ended (e.g. to drop what the thread still
        writes to from a cache, and to wait for it before reusing that);
        None: nothing is called.

    Returns
    -------
    object
        What ``fn()`` returned.

    Raises
    ------
    KeyboardInterrupt
        The signal's exception; the worker thread is abandoned (it runs to
        its end, its result dropped), :func:`abandoned_calls` is True until it
        ends, and ``on_abandon`` is called.
    BaseException
        Whatever ``fn()`` raised, re-raised in the calling thread.
    """
    if threading.current_thread() is not threading.main_thread():
        return fn()
    call = _Call(fn)
    with handling_signals():
        try:
            with _signals_deferred():  # a signal within start() raises after it, in this try
                call.thread.start()
            call.finished.wait()  # interruptible: the handler raises here
        except BaseException:
            if call.running():
                _abandoned.append(call)
                if on_abandon is not None:
                    on_abandon(call.finished)
            raise
    if call.error is not None:
        raise call.error
    return cast(T, call.value)


def holds(moment: str) -> bool:
    """Whether the test hook holds at ``moment``.

    Parameters
    ----------
    moment : str
        A moment of the test hook (see the module's docstring), e.g. ``"solve"``.

    Returns
    -------
    bool
        True when the environment variable ``LPVEST_TEST_HOLD`` equals ``moment``.
    """
    return os.environ.get("LPVEST_TEST_HOLD") == moment


_abandoned: list[_Call] = []


def abandoned_calls() -> bool:
    """Whether a call :func:`call_interruptibly` abandoned is still running.
    A process that exits then should leave with ``os._exit`` (after flushing
    its output): a native solver still running while the interpreter and the
    C++ runtime shut down can abort the process ("terminate called without
    an active exception", SIGABRT) instead of the exit status it chose.

    Returns
    -------
    bool
        True when the thread of at least one abandoned call is alive.
    """
    return any(not call.finished.is_set() for call in _abandoned)


def hold(moment: str) -> None:
    """The test hook (see the module's docstring): at ``moment``, when
    ``LPVEST_TEST_HOLD`` names it, say so in ``LPVEST_TEST_READY`` and wait
    for a signal.

    Parameters
    ----------
    moment : str
        The moment reached (see the module's docstring); nothing happens
        unless ``LPVEST_TEST_HOLD`` names it.
    """
    if not holds(moment):
        return
    with open(os.environ["LPVEST_TEST_READY"], "a", encoding="utf-8") as f:
        f.write(moment + "\n")
    threading.Event().wait()  # in the main thread a signal's handler raises here
