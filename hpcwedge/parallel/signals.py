"""The master's signals (SPEC §5): SIGUSR1 = checkpoint and go on; SIGTERM/SIGINT =
checkpoint and stop. The engine (engine.py) acts on them at safe points."""
from __future__ import annotations

import signal

from hpcwedge.errors import Interrupted


class SignalState:
    """The master's signals: SIGUSR1 = checkpoint and go on; SIGTERM/SIGINT = checkpoint
    and stop. While `defer` (inside a job) a signal only sets a flag that the job loop
    acts on at a safe point; otherwise SIGTERM/SIGINT raise Interrupted at once."""

    def __init__(self):
        self.flags: set = set()
        self.defer = False
        self.done = False
        self._old_handlers: dict = {}

    def install(self) -> None:
        """Install the handlers (main thread only; elsewhere signals stay as they are)."""
        import threading
        if threading.current_thread() is not threading.main_thread():
            return
        for sig in (signal.SIGUSR1, signal.SIGTERM, signal.SIGINT):
            self._old_handlers[sig] = signal.signal(sig, self._on_signal)

    def mark_done(self) -> None:
        """From now on the three signals change nothing (SIG_IGN, see Engine.mark_done)."""
        self.done = True
        for sig in self._old_handlers:
            signal.signal(sig, signal.SIG_IGN)

    def restore(self) -> None:
        """The handlers as they were before install()."""
        for sig, h in self._old_handlers.items():
            signal.signal(sig, h)
        self._old_handlers = {}

    def _on_signal(self, signum, frame):
        name = signal.Signals(signum).name
        if self.done:
            return
        if signum == signal.SIGUSR1:
            self.flags.add(name)
            return
        stopping = self.stop_reason() is not None
        self.flags.add("STOP:" + name)
        # only the first stop raises: a second one (mpirun forwards SIGTERM to rank 0 about a
        # second after SLURM's) must not interrupt the stop checkpoint's write
        if not self.defer and not stopping:
            self.defer = True
            raise Interrupted(name)

    def replay(self, signum: int) -> None:
        """Act on a signal that arrived before install() as if it arrived now."""
        self._on_signal(signum, None)

    def stop_reason(self) -> str | None:
        """The name of the SIGTERM/SIGINT received, if any."""
        return next((f[5:] for f in self.flags if f.startswith("STOP:")), None)

    def take_checkpoint_request(self) -> bool:
        """True once per SIGUSR1 received."""
        if "SIGUSR1" in self.flags:
            self.flags.discard("SIGUSR1")
            return True
        return False
