"""Blocks of a vector env's sub-envs in worker processes: `Shards`.

Why processes: a SpinnerDesign step is ~90 % compiled kernels that run on every thread and
~10 % Python (planning, packing, the results' objects) that runs on one, because it holds
the GIL; on many cores that tenth bounds a process (docs/performance.md, the 16-core
figures). Each worker runs its block of sub-envs as a whole vector env of its own, batch
and threads included, so the Python of the blocks runs side by side. The threads are
shared out: the workers' counts add up to `threads.thread_count()`, so processes and
threads never multiply.

Workers are fresh interpreters (the "spawn" start: nothing of the parent's threads or
numba state is inherited), so a script that makes such an env needs the usual
`if __name__ == "__main__":` guard. Each worker's sub-envs are built from the same keyword
arguments as the parent's; their results do not depend on which process or how many
threads compute them (every design is computed alone), so the bits equal one process's.
"""

from __future__ import annotations

import multiprocessing
import pickle
import signal
import threading
import time
import traceback
from contextlib import contextmanager
from multiprocessing.connection import Connection
from multiprocessing.reduction import ForkingPickler
from typing import Any, Optional

import numpy as np

from spreadgym import device, threads

_START = multiprocessing.get_context("spawn")
_CLOSE_WAIT_S = 10.0  # the workers still running this long after "close" are terminated
_OWED_WAIT_S = 1.0  # a worker whose answer is abandoned (its pipe closed) is terminated after this


@contextmanager
def _ctrl_c_held():
    """Hold a Ctrl-C (SIGINT) that arrives in the block until its end, then deliver it to
    the handler that was in place (Python's raises KeyboardInterrupt there). Only the main
    thread receives signals, so elsewhere, or under a handler set outside Python, this
    holds nothing."""
    before = signal.getsignal(signal.SIGINT)
    if threading.current_thread() is not threading.main_thread() or before is None:
        yield
        return
    held: list = []
    signal.signal(signal.SIGINT, lambda number, frame: held.append(number))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, before)
        if held:
            signal.raise_signal(signal.SIGINT)


def blocks(num_envs: int, workers: int) -> list[tuple[int, int]]:
    """[first, stop) sub-env indices of each worker: contiguous, sizes differing by one at
    most (workers <= num_envs, so none is empty)."""
    return [(int(part[0]), int(part[-1]) + 1) for part in np.array_split(np.arange(num_envs), workers)]


class Shards:
    """`workers` processes, worker w holding sub-envs blocks(num_envs, workers)[w] as a
    vector env of its own (`make(num_envs=..., **kwargs)` there, on `device_name` with its
    share of the threads). `call(name, per_block)` runs that method on every worker at once
    and returns their answers in order."""

    def __init__(self, make, num_envs: int, workers: int, device_name: str, kwargs: dict[str, Any]):
        self.blocks = blocks(num_envs, workers)
        self._pipes: list[Connection] = []
        self._processes: list = []
        self._owed: set[int] = set()  # workers whose answer (to their start or a call) is not read yet
        try:
            for (first, stop), share in zip(self.blocks, threads.shares(workers)):
                ours, theirs = _START.Pipe()
                process = _START.Process(target=_serve, args=(theirs, make, stop - first, share, device_name, kwargs),
                                         daemon=True, name=f"spreadgym-vector-worker-{len(self._pipes)}")
                with _ctrl_c_held():  # a worker started and not yet listed would escape close()
                    process.start()
                    self._pipes.append(ours)
                    self._processes.append(process)
                    self._owed.add(len(self._pipes) - 1)  # its start answer, until read
                theirs.close()
            self._answers(list(range(workers)), workers, {}, starting=True)  # built, or the first error raised
        except BaseException:
            self.close()
            raise

    def call(self, name: str, per_block: list[Optional[tuple]]) -> list:
        """Worker w runs `env.<name>(*per_block[w])` (None: w sits this call out); the answers
        in order (None for those that sat out). Every message is pickled before any is sent,
        a Ctrl-C while they go out is held until all are sent (and one while an answer is
        read, until it is read: `_received`), and the first worker error is raised once every
        asked worker has answered, so the pipes stay in step; the answers an interrupted call
        left (Ctrl-C in this process while it awaited them) are read and dropped first."""
        self._drain()
        asked = [w for w, args in enumerate(per_block) if args is not None]
        messages = {w: ForkingPickler.dumps((name, per_block[w])) for w in asked}
        failed: dict[int, BaseException] = {}
        with _ctrl_c_held():  # a message half sent, or sent and not marked owed, would put a pipe out of step
            for w in asked:
                try:
                    self._pipes[w].send_bytes(messages[w])
                    self._owed.add(w)
                except OSError:
                    failed[w] = _gone(w)
        return self._answers(asked, len(per_block), failed)

    def _answers(self, asked: list[int], size: int, failed: dict[int, BaseException], starting: bool = False) -> list:
        """Each asked worker's answer (those in `failed` already failed), then the first error raised."""
        answers: list = [None] * size
        for w in asked:
            if w in failed:
                continue
            try:
                raw = self._received(w)  # read apart from unpickling: a bad answer is still read
            except (EOFError, OSError):
                self._owed.discard(w)
                kind, value = "error", _gone(w, self._processes[w] if starting else None)
            else:
                kind, value = _unpickled(w, raw)
            if kind == "ok":
                answers[w] = value
            else:
                failed[w] = value
        if failed:
            raise failed[min(failed)]
        return answers

    def _received(self, w: int) -> bytes:
        """Worker w's next answer, read whole. A Ctrl-C while it is awaited abandons the call
        (the answer stays owed); one that arrives while it is read is held until it is read
        and no longer owed, since a message half read, or read and still owed, would put
        the pipe out of step."""
        self._pipes[w].poll(None)
        with _ctrl_c_held():
            raw = self._pipes[w].recv_bytes()
            self._owed.discard(w)
        return raw

    def _drain(self) -> None:
        """Read and drop the answers an interrupted call left in the pipes."""
        for w in sorted(self._owed):
            try:
                self._received(w)
            except (EOFError, OSError):
                self._owed.discard(w)  # gone: the next message to it says so

    def close(self) -> None:
        """Stop every worker (closing their sub-envs), waiting _CLOSE_WAIT_S at most in all.
        A worker that still owes an answer (to a call or to its start, interrupted by
        Ctrl-C) gets its pipe closed instead: one blocked sending a large answer stops at
        once, and one still working on what nobody will read (building its sub-envs, where
        numba's first compile can take a minute, or a step) is terminated after
        _OWED_WAIT_S, so an interrupted start or step returns promptly."""
        answered = {w for w in self._owed if self._pipes[w].poll(0)}  # idle since: they end at once
        for w, pipe in enumerate(self._pipes):
            if w in self._owed:
                pipe.close()  # its send fails, or its next receive ends: `_serve` returns
                continue
            try:
                pipe.send(("close", ()))
            except OSError:
                pass  # already gone
        now = time.monotonic()
        busy = self._owed - answered  # still building or computing what nobody will read
        deadline = {w: now + (_OWED_WAIT_S if w in busy else _CLOSE_WAIT_S) for w in range(len(self._processes))}
        for w, process in enumerate(self._processes):
            process.join(max(0.0, deadline[w] - time.monotonic()))
            if process.is_alive():
                process.terminate()
                process.join()
        for pipe in self._pipes:
            pipe.close()
        self._pipes, self._processes, self._owed = [], [], set()


def _serve(pipe: Connection, make, num_envs: int, share: int, device_name: str, kwargs: dict) -> None:
    """A worker's loop: build the block's vector env with `share` threads on `device_name`,
    then answer each (method, args) with ("ok", result) or ("error", exception) until
    "close". Ctrl-C is the parent's to handle (a terminal sends it to the whole process
    group), so a worker ignores it and finishes the call it is in."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    threads.set_threads(share)
    device.set_device(device_name)
    env = None
    try:
        try:
            env = make(num_envs=num_envs, **kwargs)
            answer: tuple = ("ok", None)
        except Exception as error:  # noqa: BLE001 (the parent raises it)
            answer = ("error", _portable(error))
        while True:
            try:
                pipe.send(answer)
            except OSError:
                raise  # the parent has gone, or closed this pipe (`close`): returned from below
            except Exception as error:  # noqa: BLE001 (it did not pickle, so nothing was sent)
                pipe.send(("error", RuntimeError(f"a vector env worker's answer does not pickle: "
                                                 f"{type(error).__name__}: {error}")))
            if env is None:
                return
            name, args = pipe.recv()
            if name == "close":
                return
            try:
                answer = ("ok", getattr(env, name)(*args))
            except Exception as error:  # noqa: BLE001 (the parent raises it)
                answer = ("error", _portable(error))
    except (EOFError, OSError):
        return  # the parent has gone
    finally:
        if env is not None:
            env.close()


def _unpickled(worker: int, raw: bytes) -> tuple:
    """A worker's ("ok" | "error", value) from its bytes; one that does not unpickle here
    (an object whose class this process lacks) is that worker's error."""
    try:
        return ForkingPickler.loads(raw)
    except Exception as error:  # noqa: BLE001 (any unpickling failure)
        return "error", RuntimeError(f"vector env worker {worker}'s answer does not unpickle here: "
                                     f"{type(error).__name__}: {error}")


def _gone(worker: int, starting=None) -> RuntimeError:
    """The error for a worker that stopped without an answer; `starting`: its process, when
    it stopped before its env was built."""
    if starting is not None:
        starting.join(5.0)
        return RuntimeError(f"vector env worker {worker} stopped while starting (exit code {starting.exitcode}; its "
                            "error is on stderr); a script that makes an env with workers needs "
                            "`if __name__ == \"__main__\":` around it, or its spawned workers re-run it")
    return RuntimeError(f"vector env worker {worker} stopped without an answer (killed, or out of memory?)")


def _portable(error: Exception) -> Exception:
    """`error` with the worker's traceback as a note (shown in the parent's traceback, not
    in its message), or, where it does not pickle, a RuntimeError naming it."""
    if hasattr(error, "add_note"):  # Python 3.11 on
        error.add_note("in a vector env worker process:\n" + "".join(traceback.format_exception(error)).rstrip())
    try:
        pickle.loads(pickle.dumps(error))
        return error
    except Exception:  # noqa: BLE001 (any pickling failure)
        return RuntimeError(f"{type(error).__name__}: {error}")
