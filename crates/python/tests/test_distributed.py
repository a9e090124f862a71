"""fmaps.distributed on a local two-worker Ray cluster: six generated
pairs, one worker killed while matching, every pair reported once and
equal to `fmaps batch`'s map; then the same pairs from `Mesh` objects
instead of paths. Skipped, saying so, where Ray is not
installed (`.ci/run` installs it)."""

import os
import signal
import subprocess
from itertools import combinations

import numpy as np
import pytest

import fmaps
from test_fmaps import cli

ray = pytest.importorskip("ray", reason="Ray is not installed (pip install 'fmaps[ray]')")


def busy_workers():
    """PIDs of Ray workers executing a `match` task (Ray titles its
    worker processes `ray::<task>` while they run one)."""
    pids = []
    for pid in os.listdir("/proc"):
        if not pid.isdigit():
            continue
        try:
            with open(f"/proc/{pid}/cmdline", "rb") as f:
                cmd = f.read()
        except OSError:
            continue
        if cmd.startswith(b"ray::match"):
            pids.append(int(pid))
    return pids


def test_a_collection_on_two_workers_survives_a_killed_worker(tmp_path):
    data = tmp_path / "data"
    data.mkdir()
    names = []
    for i in range(4):
        name = f"body_{i}_{i}"
        fmaps.generated_body(i, i).save(data / f"{name}.off")
        names.append(name)
    pairs = list(combinations(names, 2))
    assert len(pairs) == 6
    (tmp_path / "pairs.txt").write_text("".join(f"{a} {b}\n" for a, b in pairs))
    subprocess.run(
        [cli(), "--threads", "2", "batch", str(tmp_path / "pairs.txt"), "--data", str(data), "--out", str(tmp_path / "batch")],
        check=True,
        capture_output=True,
    )

    killed = []

    def kill_one(pair, value):
        # After the first pair, kill a worker in the middle of another.
        if not killed:
            busy = busy_workers()
            if busy:
                os.kill(busy[0], signal.SIGKILL)
                killed.append(busy[0])

    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    try:
        import fmaps.distributed as fd

        seen = []
        results = fd.match_collection(
            pairs,
            {n: str(data / f"{n}.off") for n in names},
            on_result=lambda p, v: (seen.append(p), kill_one(p, v)),
            progress=False,
        )
        # The same collection from Mesh objects (pickled into the tasks).
        from_meshes = fd.match_collection(
            pairs,
            {n: fmaps.Mesh.load(data / f"{n}.off") for n in names},
            progress=False,
        )
    finally:
        ray.shutdown()
    assert killed, "no busy worker was found to kill"
    # Every pair exactly once, each the map `fmaps batch` wrote.
    assert sorted(seen) == sorted(pairs) and len(seen) == 6
    assert set(results) == set(pairs)
    for a, b in pairs:
        want = fmaps.read_indices(tmp_path / "batch" / f"{a}_{b}.map")
        assert np.array_equal(results[(a, b)]["map_ab"], want), (a, b)
        assert np.array_equal(from_meshes[(a, b)]["map_ab"], want), (a, b)
