"""Dask clusters: the local cluster of fresh worker processes started on first use and kept
(:func:`local_client`, :func:`start_local_cluster`), connecting to a scheduler address
(:func:`connect`), and the per-client record of what was shipped to it.
"""

from __future__ import annotations

import json
import logging
import os
import subprocess
import sys
import threading
import time

from verified.execution.plan import subprocess_workers_supported
from verified.execution.worker import prepare_worker

__all__ = ["local_client", "connect", "close_local_clients", "SchedulerError", "WorkerStartError", "CONNECT_TIMEOUT", "start_local_cluster"]


#: seconds to wait for a scheduler before :class:`SchedulerError`
CONNECT_TIMEOUT = 10.0

#: seconds on top of the connect timeout for the scheduler's handshake (:func:`connect`)
HANDSHAKE_GRACE = 5.0


class SchedulerError(ConnectionError):
    """A Dask scheduler that cannot be reached (the message names the address)."""


class WorkerStartError(RuntimeError):
    """Local Dask workers that could not be started (the message says why and what to do)."""


# ----------------------------------------------------------------------------- Dask
_LOCAL: dict = {}  # workers -> (cluster, client)

#: seconds to wait for the local workers to connect (:func:`local_client`)
LOCAL_START_TIMEOUT = 120.0


def _worker_env() -> dict:
    """The environment of a local worker process: this one's, with this process's
    ``sys.path`` (a spawned process got it; a fresh interpreter needs it on
    ``PYTHONPATH``: the script's folder, a path added at run time) and Dask
    configuration (also what was set at run time with ``dask.config.set``)."""
    import dask.config  # (optional extra, only to start local workers)
    env = dict(os.environ)
    path = [os.getcwd() if p == "" else p for p in sys.path]
    env["PYTHONPATH"] = os.pathsep.join(dict.fromkeys(path))
    # (its errors only, as LocalCluster(silence_logs=ERROR): a nanny left without this
    # process logs its goodbye at INFO)
    config = dask.config.merge(dask.config.global_config, {"logging": {"distributed": "error"}})
    env["DASK_INTERNAL_INHERIT_CONFIG"] = dask.config.serialize(config)
    return env


def _subprocess_worker_class():
    """:class:`distributed.deploy.subprocess.SubprocessWorker` started as its own session
    (Ctrl-C in a terminal reaches the whole foreground process group: the workers would
    shut down with this process's KeyboardInterrupt) with :func:`_worker_env`."""
    # (asyncio: ~60 ms to import, only for this class; distributed: the optional extra)
    import asyncio

    from distributed.deploy.subprocess import SubprocessWorker

    class _Worker(SubprocessWorker):
        async def _start(self) -> None:
            opts = dict(self.worker_kwargs)
            if self.name is not None:
                opts.setdefault("name", self.name)  # the cluster tracks its workers by name
            cmd = [sys.executable, "-m", "dask", "spec", self.scheduler,
                   "--spec", json.dumps({"cls": self.worker_class, "opts": opts})]
            self.process = await asyncio.create_subprocess_exec(
                *cmd, env=_worker_env(), stdin=subprocess.DEVNULL, start_new_session=True)

    return _Worker


def start_local_cluster(workers: int):
    """(cluster, client): ``workers`` 1-thread worker processes on this machine (what
    :func:`local_client` starts, before it runs :func:`prepare_worker` in each; the caller
    closes both).

    Not ``LocalCluster``: its nannies start the workers with multiprocessing's "spawn",
    which first re-runs the calling script's top level (``__main__``) in every worker,
    so a script without ``if __name__ == "__main__":`` ran itself again in each and
    failed. Here (POSIX) the scheduler runs in this process, as in ``LocalCluster``, and
    each worker is a nanny started as a fresh interpreter, ``python -m dask spec``
    (Dask's :mod:`distributed.deploy.subprocess`), whose ``__main__`` is Dask's command
    line: the script is never imported there. Its nanny restarts a worker process that
    dies (a killed worker's chunk is retried by the scheduler). The workers are their
    own session (a terminal's Ctrl-C does not stop them) and leave when this process
    does: a worker that loses the scheduler closes, and its nanny with it."""
    # (dask.distributed: an optional extra, imported only when a cluster is asked for)
    from distributed import Client, Scheduler, SpecCluster
    from distributed.worker_memory import parse_memory_limit

    host = "127.0.0.1"
    worker = {"cls": _subprocess_worker_class(),
              "options": {"worker_class": "distributed.Nanny",
                          "worker_kwargs": {"host": host, "nthreads": 1, "silence_logs": logging.ERROR,
                                            "memory_limit": parse_memory_limit("auto", 1, workers,
                                                                                logger=logging.getLogger(__name__))}}}
    # the scheduler's HTTP server on a free port (":8787" warns when another cluster runs)
    scheduler = {"cls": Scheduler, "options": {"host": host, "port": 0, "dashboard": True,
                                               "dashboard_address": ":0"}}
    cluster = SpecCluster(workers={i: worker for i in range(workers)}, worker=worker, scheduler=scheduler,
                          name="mbs-verified-local", silence_logs=logging.ERROR)
    try:
        client = Client(cluster, set_as_default=False)
        # the nannies only start their processes: wait until every worker has connected,
        # and give up at once when one of those processes has exited
        deadline = time.monotonic() + LOCAL_START_TIMEOUT
        while True:
            try:
                client.wait_for_workers(workers, timeout=0.5)
                break
            except TimeoutError:
                codes = [getattr(getattr(w, "process", None), "returncode", None) for w in cluster.workers.values()]
                dead = [c for c in codes if c is not None]
                if dead:
                    raise RuntimeError(f"a worker process exited with code {dead[0]} while starting "
                                       "(its error is above)") from None
                if time.monotonic() > deadline:
                    raise RuntimeError(f"the workers did not connect within {LOCAL_START_TIMEOUT:g} s") from None
    except BaseException:
        cluster.close()
        raise
    return cluster, client


def local_client(workers: int):
    """A ``distributed.Client`` of a local cluster with ``workers`` processes of one
    thread each, created on first use (:func:`prepare_worker` run in every worker) and
    kept for later calls until :func:`close_local_clients` / exit.

    On POSIX the workers are fresh interpreters (:func:`start_local_cluster`): the
    calling script needs no ``if __name__ == "__main__":`` guard. Elsewhere it is a
    ``LocalCluster``, whose spawned workers re-run an unguarded script's top level:
    :class:`WorkerStartError` says so."""
    got = _LOCAL.get(workers)
    if got is not None and got[1].status == "running":
        return got[1]
    if subprocess_workers_supported():
        try:
            cluster, client = start_local_cluster(workers)
        except Exception as exc:  # noqa: BLE001 - one line, the cause named
            why = " ".join(str(exc).split()) or type(exc).__name__
            raise WorkerStartError(f"could not start {workers} local Dask worker processes ({why}); pass "
                                   "workers=1 to run in this process") from None
    else:  # pragma: no cover - Windows
        from distributed import Client, LocalCluster  # (optional extra, only for a cluster)
        try:
            cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=":0",
                                   silence_logs=logging.ERROR)
        except RuntimeError as exc:
            # Dask spawns its worker processes, and a spawned process first re-runs the
            # calling script's top level: unguarded, that reaches this call again while the
            # process is still starting, and the parent only sees "Nanny failed to start"
            raise WorkerStartError(
                f"could not start {workers} local Dask worker processes ({exc}); worker processes re-run "
                "the calling script's top level, so put it under `if __name__ == \"__main__\":`, or pass "
                "workers=1 to run in this process") from None
        client = Client(cluster, set_as_default=False)
    client.run(prepare_worker)
    client.register_worker_callbacks(prepare_worker)  # also workers restarted later (a killed worker)
    _LOCAL[workers] = (cluster, client)
    return client


def close_local_clients():
    """Shut down the local clusters :func:`local_client` started."""
    # the nannies' and scheduler's goodbyes (INFO lines, a WARNING about the graph)
    quiet = [logging.getLogger(n) for n in list(logging.root.manager.loggerDict) if n.startswith("distributed")]
    levels = [lg.level for lg in quiet]
    for lg in quiet:
        lg.setLevel(logging.CRITICAL)
    try:
        while _LOCAL:
            _, (cluster, client) = _LOCAL.popitem()
            for key in [k for k in _SHIPPED if k[0] == id(client)]:
                _SHIPPED.pop(key)
            try:
                client.close()
                cluster.close()
            except Exception:  # noqa: BLE001 - shutting down anyway
                pass
    finally:
        for lg, lv in zip(quiet, levels):
            lg.setLevel(lv)


def connect(address: str, timeout: float | None = None):
    """A ``distributed.Client`` for the scheduler at ``address`` (``tcp://host:port``).
    Raises :class:`SchedulerError` naming the address when it cannot be reached within
    ``timeout`` seconds (default :data:`CONNECT_TIMEOUT`)."""
    if not isinstance(address, str) or "://" not in address and ":" not in address:
        raise ValueError(f"scheduler address must look like tcp://host:port, got {address!r}")
    try:
        from distributed import Client  # (optional extra: its absence is the error below)
    except ImportError:
        raise SchedulerError(f"cannot use the Dask scheduler at {address}: dask.distributed is not installed "
                             "(pip install 'mbs-verified[parallel]')") from None
    timeout = CONNECT_TIMEOUT if timeout is None else float(timeout)
    # Client(timeout=) bounds the connection but not the handshake: an address that
    # accepts connections and does not answer as a scheduler (a dashboard port, an HTTP
    # server) hung for ever. So the client is made in a daemon thread and waited for.
    out: dict = {}

    def make():
        try:
            out["client"] = Client(address, timeout=timeout, set_as_default=False)
        except BaseException as e:  # noqa: BLE001 - reported below, in one line
            out["error"] = e
    th = threading.Thread(target=make, name="mbs-verified-connect", daemon=True)
    th.start()
    th.join(timeout + HANDSHAKE_GRACE)
    if "client" in out:
        return out["client"]
    e = out.get("error")
    why = "no answer as a Dask scheduler" if e is None else type(e).__name__
    raise SchedulerError(f"cannot reach the Dask scheduler at {address} within {timeout:g} s ({why})")


def _identity(x):
    return x


def _thread_count(client) -> int:
    """Threads of the workers connected to ``client``'s scheduler now (0 when it cannot
    be asked)."""
    try:
        return int(sum(client.nthreads().values()))
    except Exception:  # noqa: BLE001 - the scheduler may be gone too: not this check's error
        return -1


_SHIPPED: dict = {}  # (client id, token) -> (future of the shipped problem, workers warmed)
