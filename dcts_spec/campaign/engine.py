"""Where the samples run: Ray actors (this machine by default, a cluster given its address), or a
plain serial loop in this process (the baseline the throughput is compared with).

Either pool yields rows as samples finish, in whatever order they finish; each worker is one
SampleRunner that keeps its loaded spec and bundles between samples.
"""

from __future__ import annotations

import logging
import signal
import socket
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any, Protocol

from ..files import stop_signal
from ..solve.sensitivity import available_cpus
from .runner import CampaignInputs, SampleRunner

IN_FLIGHT = 2  # samples queued per Ray worker: it never waits for the driver between samples


@dataclass
class Throughput:
    """Samples run by this invocation and how long they took (startup: the pool's, not counted)."""

    engine: str
    workers: int
    samples: int = 0
    seconds: float = 0.0
    startup_seconds: float = 0.0

    @property
    def samples_per_second(self) -> float | None:
        return self.samples / self.seconds if self.seconds > 0 else None

    def to_dict(self) -> dict[str, Any]:
        return {"engine": self.engine, "workers": self.workers, "samples": self.samples,
                "seconds": self.seconds, "startup_seconds": self.startup_seconds,
                "samples_per_second": self.samples_per_second}


class Pool(Protocol):
    throughput: Throughput

    def map(self, indices: list[int], parameters: dict[str, Any] | None = None) -> Iterator[dict[str, Any]]: ...


class SerialPool:
    """One SampleRunner in this process, one sample after the other."""

    def __init__(self, runner: SampleRunner):
        self.runner = runner
        self.throughput = Throughput("serial", 1)

    def map(self, indices: list[int], parameters: dict[str, Any] | None = None) -> Iterator[dict[str, Any]]:
        for index in indices:
            if (signum := stop_signal()) is not None:  # (a stop whose exception was lost: files.request_stop)
                raise SystemExit(128 + signum)
            start = time.perf_counter()
            row = self.runner.run(index, parameters)
            self.throughput.seconds += time.perf_counter() - start
            self.throughput.samples += 1
            yield row


class RayPool:
    """One Ray actor per CPU of the Ray cluster, each a SampleRunner."""

    def __init__(self, inputs: CampaignInputs, workers: int | None = None):
        import ray

        start = time.perf_counter()
        cpus = int(ray.cluster_resources().get("CPU", 1))
        count = max(1, min(workers or cpus, cpus))
        self._actor_class = ray.remote(num_cpus=1)(SampleRunner)
        self._inputs = inputs
        self._actors = [self._actor_class.remote(inputs) for _ in range(count)]
        self._replacements: dict[Any, Any] = {}  # a dead actor → the one started in its place
        ray.get([a.__ray_ready__.remote() for a in self._actors])
        self.throughput = Throughput("ray", count, startup_seconds=time.perf_counter() - start)

    def map(self, indices: list[int], parameters: dict[str, Any] | None = None) -> Iterator[dict[str, Any]]:
        import ray
        from ray.exceptions import RayActorError, RayError

        todo = iter(indices)
        retry: list[int] = []  # samples whose worker died under them, to run once more
        failed: set[int] = set()
        pending: dict[Any, tuple[Any, int]] = {}  # task → (its actor, its sample)

        def submit(actor: Any) -> None:
            index = retry.pop() if retry else next(todo, None)
            if index is not None:
                pending[actor.run.remote(index, parameters)] = (actor, index)

        for actor in self._actors:
            for _ in range(IN_FLIGHT):
                submit(actor)
        start, before = time.perf_counter(), self.throughput.seconds
        try:
            while pending:
                done, _ = ray.wait(list(pending), num_returns=1)
                actor, index = pending.pop(done[0])
                try:
                    row = ray.get(done[0])
                except RayActorError as error:
                    # The worker died (a crash in C, out of memory): a new one takes its place and
                    # the sample runs once more; dying twice, it is recorded as an error.
                    actor = self._replace(actor)
                    row = None if index not in failed else {"index": index, "status": "error",
                                                           "error": f"the worker died twice running it: {error}"}
                    if row is None:
                        failed.add(index)
                        retry.append(index)
                except RayError as error:
                    row = {"index": index, "status": "error", "error": f"{type(error).__name__}: {error}"}
                submit(actor)
                if row is not None:
                    self.throughput.samples += 1
                    self.throughput.seconds = before + time.perf_counter() - start
                    yield row
        finally:
            for ref in pending:  # an interrupted map: the queued samples are not wanted any more
                ray.cancel(ref)

    def _replace(self, dead: Any) -> Any:
        """The actor in the dead one's place (started once, whichever of its tasks reports first)."""
        if dead not in self._replacements:
            self._replacements[dead] = self._actor_class.remote(self._inputs)
            self._actors[self._actors.index(dead)] = self._replacements[dead]
        return self._replacements[dead]

    def close(self) -> None:
        import ray

        for actor in self._actors:
            ray.kill(actor)


class ClusterUnreachable(RuntimeError):
    """No Ray cluster answers at the address given."""


def check_address(address: str, timeout: float = 5.0) -> None:
    """Raise ClusterUnreachable unless something listens at a Ray cluster's host:port (`auto`:
    Ray finds it). Ray itself retries for minutes, saying nothing but its own log lines."""
    if address == "auto":
        return
    host, _, port = address.removeprefix("ray://").rpartition(":")
    if not host or not port.isdigit():
        raise ClusterUnreachable(f"--address {address!r}: expected host:port, ray://host:port or auto")
    try:
        socket.create_connection((host.strip("[]"), int(port)), timeout=timeout).close()
    except OSError as error:
        raise ClusterUnreachable(f"--address {address}: no Ray cluster answers there ({error.strerror or error}); "
                                 "start one (ray start --head) or leave --address out for a local session") from None


@contextmanager
def ray_session(address: str | None = None, cpus: int | None = None, quiet: bool = False) -> Iterator[None]:
    """Ray on this machine (no setup: a local session started and stopped here), or the cluster at
    `address`; a session already open in this process (a test's, a notebook's) is used as it is.
    `quiet`: Ray's notices at start-up (token authentication) are not printed, its errors are."""
    import ray

    if ray.is_initialized():
        yield
        return
    options: dict[str, Any] = {"include_dashboard": False, "log_to_driver": False, "configure_logging": False}
    if address is None:
        options["num_cpus"] = cpus or available_cpus()
    handlers = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    ray_logger = logging.getLogger("ray")
    level = ray_logger.level
    if quiet:
        ray_logger.setLevel(logging.ERROR)
    try:
        ray.init(address=address, **options)
    finally:
        ray_logger.setLevel(level)
    # Ray's core worker installs its own signal handlers: on SIGTERM it dumped a stack trace and
    # exited with 15, where the command stops cleanly (its samples kept) and exits with 143
    if threading.current_thread() is threading.main_thread():
        for s, handler in handlers.items():
            if handler is not None:
                signal.signal(s, handler)
    try:
        yield
    finally:
        ray.shutdown()
