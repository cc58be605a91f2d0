"""Benchmark and sweep runs on a Dask distributed cluster.

The runners map a pure, picklable task over (tracker, sequence) pairs with any
`concurrent.futures.Executor`; `cluster_executor(address)` is that executor for a running Dask
scheduler (`dask scheduler` + `dask worker` processes, or a `LocalCluster`). Only the task
arguments travel: a sequence is its frame paths and ground truth, so every worker must have this
package installed and see the data at the same path as the machine that submits (a shared
filesystem, or the same copy at the same place). Results come back to the submitting machine,
which saves, resumes and scores them exactly as in a local run.
"""

from __future__ import annotations

import argparse
import asyncio
import logging
import os
from collections.abc import Iterable, Iterator
from concurrent.futures import CancelledError, Executor
from contextlib import AbstractContextManager, contextmanager, nullcontext
from pathlib import Path

from autotrack.errors import AutoTrackError, InputError
from autotrack.extras import install_hint

CONNECT_TIMEOUT_S = 30.0
"""How long to wait for the scheduler to answer and for at least one worker to join."""

INSTALL_HINT = f"install the cluster extra: {install_hint('cluster')}"

RESUME_HINT = "the runs saved so far are kept: rerun the same command to resume"


class ClusterError(AutoTrackError):
    """The Dask scheduler cannot be reached, has no workers, or its workers cannot run our tasks."""


def _worker_report(paths: tuple[str, ...]) -> dict[str, object]:
    """Run on each worker: the autotrack version it imports and which paths it cannot see."""
    import autotrack

    return {
        "version": autotrack.__version__,
        "missing": [path for path in paths if not os.path.exists(path)],
    }


def normalise_address(address: str) -> str:
    """'HOST:PORT' or 'tcp://HOST:PORT' -> 'tcp://HOST:PORT'; InputError for anything else."""
    text = address.strip()
    if "://" not in text:
        text = f"tcp://{text}"
    scheme, _, rest = text.partition("://")
    host, _, port = rest.rpartition(":")
    if scheme not in ("tcp", "tls") or not host or not port.isdigit():
        raise InputError(
            f"--scheduler must look like tcp://HOST:PORT (the address `dask scheduler` prints), "
            f"got {address!r}"
        )
    return text


@contextmanager
def cluster_executor(
    address: str,
    *,
    shared_paths: Iterable[str | Path] = (),
    timeout_s: float = CONNECT_TIMEOUT_S,
) -> Iterator[Executor]:
    """A concurrent.futures Executor whose tasks run on the Dask cluster at `address`.

    Before yielding, checks that a worker has joined, that every worker imports the same
    autotrack version as this process, and that every worker sees `shared_paths` (the benchmark
    root, the colour table): a cluster without the shared filesystem fails here with one line,
    not halfway through a run. The client is closed on exit; the cluster keeps running.
    """
    try:
        from distributed import Client, KilledWorker
    except ImportError as error:
        raise ClusterError(f"--scheduler needs Dask distributed: {INSTALL_HINT}") from error
    import autotrack

    address = normalise_address(address)
    try:
        client = Client(address, timeout=timeout_s, set_as_default=False)
    except (OSError, TimeoutError) as error:
        raise ClusterError(f"cannot reach the Dask scheduler at {address}: {error}") from None
    try:
        try:
            client.wait_for_workers(1, timeout=timeout_s)
        except TimeoutError:
            raise ClusterError(
                f"the Dask scheduler at {address} has no workers (waited {timeout_s:g} s): "
                f"start some with `dask worker {address} --nthreads 1`"
            ) from None
        paths = tuple(str(Path(path).resolve()) for path in shared_paths)
        try:
            reports = client.run(_worker_report, paths)
        except ModuleNotFoundError as error:
            raise ClusterError(
                f"a worker of {address} cannot import {error.name}: install autotrack-studio "
                f"on every worker"
            ) from None
        for worker, report in sorted(reports.items()):
            if report["version"] != autotrack.__version__:
                raise ClusterError(
                    f"worker {worker} runs autotrack-studio {report['version']}, this machine "
                    f"{autotrack.__version__}: install the same version on every worker"
                )
            if report["missing"]:
                raise ClusterError(
                    f"worker {worker} cannot see {report['missing'][0]}: workers need the data "
                    f"at the same path as this machine (a shared filesystem)"
                )
        executor = client.get_executor(pure=False)
        try:
            with _quiet_reconnects():
                yield executor
        except KilledWorker as error:
            raise ClusterError(
                f"a Dask worker died while running {error.task} (out of memory, or killed); "
                f"{RESUME_HINT}"
            ) from None
        except (CancelledError, asyncio.CancelledError, OSError) as error:
            # Dask cancels every pending future when the client loses its scheduler.
            if client.status == "running" and not isinstance(error, OSError):
                raise
            raise ClusterError(
                f"lost the connection to the Dask scheduler at {address} (it stopped or the "
                f"network failed); {RESUME_HINT} once the scheduler is back"
            ) from None
        finally:
            executor.shutdown(wait=False)
    finally:
        with _quiet_reconnects():
            client.close()


@contextmanager
def _quiet_reconnects() -> Iterator[None]:
    """Keep Dask's client from logging a traceback for each failed reconnection: a lost
    scheduler is reported once, as a ClusterError."""
    logger = logging.getLogger("distributed.client")
    level = logger.level
    logger.setLevel(logging.CRITICAL)
    try:
        yield
    finally:
        logger.setLevel(level)


def cluster_executor_for(args: argparse.Namespace) -> AbstractContextManager[Executor | None]:
    """The executor a `bench`/`sweep` command line asks for: None (local run, `--jobs`) without
    `--scheduler`, else the cluster's, checked to see `root` and `colour_table`."""
    if args.scheduler is None:
        return nullcontext()
    if args.jobs != 1:
        raise InputError("give --jobs or --scheduler, not both (the cluster sets the parallelism)")
    shared = [args.root] + ([args.colour_table] if args.colour_table is not None else [])
    return cluster_executor(args.scheduler, shared_paths=shared)
