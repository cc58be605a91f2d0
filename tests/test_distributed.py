"""Benchmarks and sweeps on a real Dask cluster (two worker processes on 127.0.0.1) give the
same result files, JSON and tables as a local run; sweeps parse their grid and resume."""

from __future__ import annotations

import csv
import json
import os
import re
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from autotrack.cli import main
from autotrack.errors import InputError
from autotrack.evaluation.datasets import load_sequences
from autotrack.evaluation.distributed import ClusterError, cluster_executor, normalise_address
from autotrack.evaluation.sweep import (
    GridAxis,
    grid_combinations,
    limit_frames,
    parse_grid,
    run_sweep,
    sweep_rows,
)
from autotrack.params import TrackerParams
from tests.test_benchmark import _write_moving_square

distributed = pytest.importorskip("distributed", reason="the [cluster] extra is not installed")


@pytest.fixture(scope="module")
def cluster():
    """A real cluster: a scheduler and two single-thread worker processes, all on 127.0.0.1."""
    with distributed.LocalCluster(
        n_workers=2,
        threads_per_worker=1,
        processes=True,
        host="127.0.0.1",
        dashboard_address=None,
    ) as local_cluster:
        yield local_cluster


@pytest.fixture
def scheduler_address(cluster) -> str:
    return cluster.scheduler_address


def _tasks_run_on(cluster, function_name: str) -> int:
    """How many tasks of this function the cluster's scheduler has seen finish."""
    prefix = cluster.scheduler.task_prefixes.get(function_name)
    return 0 if prefix is None else prefix.state_counts["memory"] + prefix.state_counts["released"]


@pytest.fixture(scope="module")
def synthetic_root(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("cluster") / "Synthetic"
    _write_moving_square(root / "right", 12, (2, 1), seed=1)
    _write_moving_square(root / "down", 9, (1, 2), seed=2)
    return root


def _result_files(folder: Path) -> dict[str, str]:
    """Every box file under `folder` (relative path -> text): what other toolkits read."""
    return {str(p.relative_to(folder)): p.read_text() for p in sorted(folder.rglob("*.txt"))}


def _without_speed(document: dict) -> dict:
    """A bench JSON without its timing figures and where they were measured (the only things a
    cluster may change)."""
    document.pop("machine")
    for tracker in document["trackers"].values():
        tracker.pop("fps"), tracker.pop("fps_overall")
        for sequence in tracker["sequences"].values():
            sequence.pop("fps")
    return document


def test_bench_on_a_dask_cluster_gives_the_local_run_files_json_and_plots(
    cluster, scheduler_address, synthetic_root, tmp_path, capsys
):
    base = ["bench", str(synthetic_root), "--trackers", "autotrack,kcf", "--plots", "--no-progress"]
    local, remote = tmp_path / "local", tmp_path / "remote"
    assert main([*base, "--out", str(local), "--json", str(tmp_path / "local.json")]) == 0
    argv = [*base, "--out", str(remote), "--json", str(tmp_path / "remote.json")]
    assert main([*argv, "--scheduler", scheduler_address]) == 0
    assert "4 runs tracked, 0 resumed" in capsys.readouterr().out
    assert _tasks_run_on(cluster, "run_task") == 4
    assert _result_files(remote) == _result_files(local)
    assert len(_result_files(local)) == 4
    local_json = json.loads((tmp_path / "local.json").read_text())
    remote_json = json.loads((tmp_path / "remote.json").read_text())
    assert local_json["machine"]["logical_cores"] and remote_json["machine"] is None
    assert _without_speed(remote_json) == _without_speed(local_json)
    plots = sorted(path.name for path in (local / "plots").glob("*.png"))
    assert plots and sorted(path.name for path in (remote / "plots").glob("*.png")) == plots


def test_sweep_on_a_dask_cluster_matches_the_local_sweep_and_resumes(
    cluster, scheduler_address, synthetic_root, tmp_path, capsys
):
    grid = ["--grid", "phi=0.2,0.3", "--grid", "delta=0.1,0.2"]
    base = ["sweep", str(synthetic_root), *grid, "--frames", "8", "--no-progress"]
    local, remote = tmp_path / "local", tmp_path / "remote"
    assert main([*base, "--out", str(local)]) == 0
    assert main([*base, "--out", str(remote), "--scheduler", scheduler_address]) == 0
    printed = capsys.readouterr().out
    assert "4 combinations x 2 sequences (first 8 frames of each, 16 frames)" in printed
    assert "8 runs tracked, 0 resumed" in printed
    assert _tasks_run_on(cluster, "run_combination") == 8
    assert _result_files(remote) == _result_files(local)
    assert len(_result_files(local)) == 8

    def scores(folder: Path) -> list[tuple[str, ...]]:
        with (folder / "sweep.csv").open() as handle:
            rows = list(csv.DictReader(handle))
        return [(r["phi"], r["delta"], r["precision"], r["auc"], r["frames"]) for r in rows]

    assert scores(remote) == scores(local)
    assert [row[:2] for row in scores(local)] == [
        ("0.2", "0.1"),
        ("0.2", "0.2"),
        ("0.3", "0.1"),
        ("0.3", "0.2"),
    ]
    for name in ("sweep.md", "sweep.json", "sweep.png"):
        assert (remote / name).is_file()
    assert json.loads((remote / "sweep.json").read_text())["grid"] == {
        "phi": [0.2, 0.3],
        "delta": [0.1, 0.2],
    }
    # An interrupted sweep: one run's files are missing; only that run is tracked again.
    (remote / "runs" / "phi=0.3_delta=0.2" / "down.time.json").unlink()
    assert main([*base, "--out", str(remote), "--scheduler", scheduler_address]) == 0
    assert "1 runs tracked, 7 resumed" in capsys.readouterr().out
    assert _result_files(remote) == _result_files(local)


def test_cluster_executor_refuses_workers_that_cannot_see_the_data(scheduler_address, tmp_path):
    missing = tmp_path / "not-shared"
    with (
        pytest.raises(ClusterError, match="cannot see .*not-shared.*same path"),
        cluster_executor(scheduler_address, shared_paths=[missing]),
    ):
        pass


def test_unreachable_scheduler_is_one_line_on_the_command_line(synthetic_root, tmp_path, capsys):
    with socket.socket() as probe:  # a free port nobody listens on
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    with (
        pytest.raises(ClusterError, match="cannot reach the Dask scheduler"),
        cluster_executor(f"127.0.0.1:{port}", timeout_s=2),
    ):
        pass
    argv = ["bench", str(synthetic_root), "--trackers", "kcf", "--out", str(tmp_path)]
    assert main([*argv, "--scheduler", "tcp://127.0.0.1:8786", "--jobs", "2"]) == 2
    error = capsys.readouterr().err.strip()
    assert error == (
        "autotrack: error: give --jobs or --scheduler, not both (the cluster sets the parallelism)"
    )


def test_scheduler_addresses_are_normalised_or_refused():
    assert normalise_address("127.0.0.1:8786") == "tcp://127.0.0.1:8786"
    assert normalise_address(" tcp://node1:8786 ") == "tcp://node1:8786"
    for bad in ("node1", "http://node1:8786", "tcp://:8786", "tcp://node1:port"):
        with pytest.raises(InputError, match="tcp://HOST:PORT"):
            normalise_address(bad)


def test_grid_values_take_the_parameter_types_and_combine_in_order():
    axes = parse_grid(["phi=0.2, 0.3,0.2", "num_scales=17,33", "adaptive_spatial=true,0"])
    assert axes == (
        GridAxis("phi", (0.2, 0.3)),
        GridAxis("num_scales", (17, 33)),
        GridAxis("adaptive_spatial", (True, False)),
    )
    combinations = grid_combinations(TrackerParams(), axes)
    assert len(combinations) == 8
    assert combinations[0].label == "phi=0.2_num_scales=17_adaptive_spatial=True"
    assert combinations[-1].params == TrackerParams(phi=0.3, num_scales=33, adaptive_spatial=False)
    assert parse_grid(["theta_update=paper,release"])[0].values == ("paper", "release")


@pytest.mark.parametrize(
    ("spec", "message"),
    [
        ("ph=0.2", "not a tracker parameter (did you mean phi?)"),
        ("phi", "must be NAME=V1,V2"),
        ("phi=", "no values"),
        ("phi=abc", "'abc' is not a finite number"),
        ("num_scales=1.5", "is not an integer"),
        ("theta_update=fast", "is not release / paper / reference"),
        ("colour_feature=none", "with --color-names"),
    ],
)
def test_bad_grids_are_refused_with_a_message(spec, message):
    with pytest.raises(InputError, match=re.escape(message)):
        parse_grid([spec])


def test_invalid_combinations_and_repeated_axes_are_refused():
    with pytest.raises(InputError, match="given twice"):
        parse_grid(["phi=0.2", "phi=0.3"])
    with pytest.raises(InputError, match="invalid tracker parameters"):
        grid_combinations(TrackerParams(), parse_grid(["cell_size=0,4"]))


def test_sweep_refuses_a_folder_of_other_parameters_and_resumes_its_own(synthetic_root, tmp_path):
    sequences = limit_frames(load_sequences(synthetic_root), 5)
    axes = parse_grid(["phi=0.2,0.3"])
    first = run_sweep(sequences, grid_combinations(TrackerParams(), axes), tmp_path, progress=False)
    assert (first.benchmark.computed, first.benchmark.resumed) == (4, 0)
    again = run_sweep(sequences, grid_combinations(TrackerParams(), axes), tmp_path, progress=False)
    assert (again.benchmark.computed, again.benchmark.resumed) == (0, 4)
    rows_first, rows_again = sweep_rows(first), sweep_rows(again)
    assert [(r.precision, r.auc) for r in rows_again] == [(r.precision, r.auc) for r in rows_first]
    for key, result in first.benchmark.results.items():
        np.testing.assert_allclose(again.benchmark.results[key].boxes, result.boxes, atol=1e-4)
    other = TrackerParams(adaptive_spatial=False)
    with pytest.raises(InputError, match="holds results of other parameters"):
        run_sweep(sequences, grid_combinations(other, axes), tmp_path, progress=False)


def test_run_combination_tracks_with_the_combination_parameters(synthetic_root):
    from autotrack.evaluation.benchmark import run_task
    from autotrack.evaluation.sweep import run_combination

    sequence = limit_frames(load_sequences(synthetic_root), 6)[0]
    default = run_combination("default", TrackerParams(), sequence)
    assert (default.tracker, default.sequence, default.frames) == ("default", sequence.name, 6)
    np.testing.assert_array_equal(default.boxes, run_task("autotrack", sequence).boxes)
    one_step = run_combination("admm_iterations=1", TrackerParams(admm_iterations=1), sequence)
    assert np.abs(one_step.boxes - default.boxes).max() > 1.0


def test_sweep_in_local_processes_matches_the_inline_sweep(synthetic_root, tmp_path):
    sequences = limit_frames(load_sequences(synthetic_root), 5)
    combinations = grid_combinations(TrackerParams(), parse_grid(["admm_iterations=1,4"]))
    inline = run_sweep(sequences, combinations, tmp_path / "inline", progress=False)
    pooled = run_sweep(sequences, combinations, tmp_path / "pool", jobs=2, progress=False)
    assert pooled.benchmark.computed == inline.benchmark.computed == 4
    for key, result in inline.benchmark.results.items():
        np.testing.assert_array_equal(pooled.benchmark.results[key].boxes, result.boxes)
    with pytest.raises(InputError, match="--jobs must be at least 1"):
        run_sweep(sequences, combinations, tmp_path / "bad", jobs=0, progress=False)


def test_scheduler_without_dask_installed_names_the_extra(monkeypatch):
    monkeypatch.setitem(sys.modules, "distributed", None)  # as if the extra were not installed
    with (
        pytest.raises(ClusterError, match=r"pip install 'autotrack-studio\[cluster\]'"),
        cluster_executor("tcp://127.0.0.1:8786"),
    ):
        pass


def test_a_worker_dying_mid_run_is_one_cluster_error():
    import dask

    with (
        dask.config.set({"distributed.scheduler.allowed-failures": 0}),
        distributed.LocalCluster(
            n_workers=1, threads_per_worker=1, host="127.0.0.1", dashboard_address=None
        ) as doomed,
        pytest.raises(ClusterError, match="a Dask worker died while running .*rerun the same"),
        cluster_executor(doomed.scheduler_address) as executor,
    ):
        executor.submit(os._exit, 1).result()  # the worker process exits under the task


def _free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def _start_cluster_processes(port: int) -> list[subprocess.Popen]:
    """A `dask scheduler` process and one `dask worker` process on 127.0.0.1:`port`."""
    dask = str(Path(sys.executable).parent / "dask")
    quiet = {"stdout": subprocess.DEVNULL, "stderr": subprocess.DEVNULL}
    address = f"tcp://127.0.0.1:{port}"
    scheduler_argv = ["scheduler", "--host", "127.0.0.1", "--port", str(port), "--no-dashboard"]
    scheduler = subprocess.Popen([dask, *scheduler_argv], **quiet)
    worker_argv = ["worker", address, "--nthreads", "1", "--no-dashboard"]
    worker = subprocess.Popen([dask, *worker_argv], **quiet)
    return [scheduler, worker]


def _stop(processes: list[subprocess.Popen]) -> None:
    for process in processes:
        if process.poll() is None:
            process.kill()
        process.wait(timeout=30)


@pytest.mark.slow
def test_a_killed_scheduler_ends_the_sweep_in_one_line_and_a_rerun_resumes(tmp_path, capsys):
    root = tmp_path / "Synthetic"
    for number in range(3):
        _write_moving_square(root / f"square{number}", 40, (1, 1), seed=number)
    out = tmp_path / "sweep"
    port = _free_port()
    argv = ["sweep", str(root), "--grid", "phi=0.2,0.3", "--grid", "delta=0.1,0.2"]
    argv += ["--out", str(out), "--no-progress", "--scheduler", f"tcp://127.0.0.1:{port}"]
    processes = _start_cluster_processes(port)
    try:

        def kill_scheduler_after_the_first_run() -> None:
            deadline = time.monotonic() + 300
            while not list(out.rglob("*.txt")) and time.monotonic() < deadline:
                time.sleep(0.05)
            processes[0].kill()  # the scheduler process, not a worker

        killer = threading.Thread(target=kill_scheduler_after_the_first_run)
        killer.start()
        assert main(argv) == 2
        killer.join()
    finally:
        _stop(processes)
    error = capsys.readouterr().err.strip()
    assert error == (
        f"autotrack: error: lost the connection to the Dask scheduler at tcp://127.0.0.1:{port} "
        "(it stopped or the network failed); the runs saved so far are kept: rerun the same "
        "command to resume once the scheduler is back"
    )
    kept = len(list(out.rglob("*.txt")))
    assert 1 <= kept < 12
    processes = _start_cluster_processes(port)
    try:
        assert main(argv) == 0
    finally:
        _stop(processes)
    assert f"{12 - kept} runs tracked, {kept} resumed" in capsys.readouterr().out
    assert len(list(out.rglob("*.txt"))) == 12
