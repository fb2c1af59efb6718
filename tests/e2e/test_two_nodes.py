"""A sweep and a sharded evaluation on a two-node Ray cluster on this machine
(`ray.cluster_utils.Cluster`, every node on 127.0.0.1): a head with no CPUs, which runs nothing,
and a second node with 2 CPUs (and the custom resource `far`), which runs every task and actor.

Where `unshare` can give a process its own mount namespace, the cluster's worker processes run
in one where the directory the driver writes to (`driver_disk`) is an empty tmpfs: they do not
see the driver's working directory or the sweep's --out, as on a node without shared storage.

- a sweep whose --out the nodes see writes its runs there (the ordinary multi-node case), and
  its tables equal an in-process sweep's;
- a sweep whose --out (relative to the driver's working directory) the nodes do not see: the
  runs are made on the node and their files sent back and written into --out by the driver;
  the tables, the runs' files and a resume (more generations) equal the in-process sweep's;
- `evolve --eval-workers 2` with its run directory where the nodes cannot see it: the shards
  need nothing on disk, and the results equal the unsharded run's.

Slow (a cluster start and several Ray sweeps, about a minute on 2 CPUs): `pytest -m slow`.
"""

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from test_distributed import SIZE, _last_records, _only_run, _summary, invoke, ok

pytestmark = [pytest.mark.slow, pytest.mark.subprocess]

LOOPBACK = "127.0.0.1"
SWEEP = ["sweep", *SIZE, "--generations", "2", "--budgets", "300,600", "--seeds", "0"]


def _can_hide_dirs() -> bool:
    """Whether `unshare -rm` can mount a tmpfs here (user and mount namespaces allowed)."""
    if shutil.which("unshare") is None:
        return False
    r = subprocess.run(
        ["unshare", "-rm", "sh", "-c", "mount -t tmpfs tmpfs /mnt"], capture_output=True
    )
    return r.returncode == 0


@pytest.fixture(scope="module")
def two_nodes(tmp_path_factory):
    """(ray, driver_disk, hidden): Ray connected to a two-node loopback cluster; driver_disk a
    directory the nodes' workers do not see when `hidden` is True."""
    ray = pytest.importorskip("ray")
    from ray._private import services
    from ray.cluster_utils import Cluster

    os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
    disk = tmp_path_factory.mktemp("driver_disk")
    hidden = _can_hide_dirs()
    runtime_env = None
    if hidden:
        wrapper = tmp_path_factory.mktemp("wrapper") / "python"
        wrapper.write_text(
            "#!/bin/sh\n"
            f'exec unshare -rm sh -c \'mount -t tmpfs tmpfs "$0" && exec "$@"\' '
            f"'{disk}' '{sys.executable}' \"$@\"\n"
        )
        wrapper.chmod(0o755)
        runtime_env = {"py_executable": str(wrapper)}
    node = {"node_ip_address": LOOPBACK, "object_store_memory": 80 * 2**20}
    cluster = Cluster(
        initialize_head=True, head_node_args={**node, "num_cpus": 0, "include_dashboard": False}
    )
    cluster.add_node(**node, num_cpus=2, resources={"far": 2})
    # Ray turns a loopback address into the machine's outward one before joining; keep it
    mp = pytest.MonkeyPatch()
    mp.setattr(services, "resolve_ip_for_localhost", lambda host: host)
    try:
        ray.init(address=cluster.address, runtime_env=runtime_env, log_to_driver=False)
        yield ray, disk, hidden
    finally:
        ray.shutdown()
        cluster.shutdown()
        mp.undo()


def test_cluster_is_two_loopback_nodes_and_work_runs_on_the_second(two_nodes):
    ray, disk, hidden = two_nodes
    nodes = [n for n in ray.nodes() if n["Alive"]]
    assert len(nodes) == 2 and {n["NodeManagerAddress"] for n in nodes} == {LOOPBACK}
    (far,) = [n for n in nodes if n["Resources"].get("far")]
    (head,) = [n for n in nodes if n is not far]
    assert head["Resources"].get("CPU", 0) == 0 and far["Resources"]["CPU"] == 2
    (disk / "mark").write_text("driver")

    def node_view(path: str):  # defined here: sent by value, not by this module's name
        return ray.get_runtime_context().get_node_id(), os.path.exists(path)

    probe = ray.remote(num_cpus=1, resources={"far": 1})(node_view)
    node_id, sees = ray.get(probe.remote(str(disk / "mark")))
    assert node_id == far["NodeID"] and sees is not hidden


@pytest.fixture(scope="module")
def in_process(tmp_path_factory):
    """The sweep in this process: 2 generations, then resumed to 3 (copies of --out)."""
    root = tmp_path_factory.mktemp("in_process")
    ok(invoke(*SWEEP, "--out", root / "sweep"))
    shutil.copytree(root / "sweep", root / "two")
    ok(invoke(*SWEEP, "--generations", 3, "--out", root / "sweep"))
    return root / "two", root / "sweep"


def _same_runs(out: Path, ref: Path) -> None:
    for name in ("table.csv", "table.md"):
        assert (out / name).read_bytes() == (ref / name).read_bytes(), name
    runs = sorted(p.name for p in ref.iterdir() if p.is_dir())
    assert runs == sorted(p.name for p in out.iterdir() if p.is_dir()) and len(runs) == 2
    for run in runs:
        a, b = out / run, ref / run
        assert (a / "config.toml").read_bytes() == (b / "config.toml").read_bytes()
        assert _last_records(a / "teams.jsonl") == _last_records(b / "teams.jsonl")
        assert _summary(a) == _summary(b)
        assert (a / "checkpoint.pt").is_file() and not (a / "run.lock").exists()


def test_sweep_with_shared_out(two_nodes, in_process, tmp_path):
    out = tmp_path / "sweep"  # outside driver_disk: the nodes see it
    r = ok(invoke(*SWEEP, "--out", out, "--workers", 2))
    assert "finished (2 done, 0 running, 0 failed of 2)  elapsed " in r.output
    ends = [ln for ln in r.output.splitlines() if ": finished (" in ln]
    assert len(ends) == 2 and all(", left " in ln for ln in ends), r.output
    assert "files were written here" not in r.output
    _same_runs(out, in_process[0])


def test_sweep_whose_out_the_nodes_do_not_see(two_nodes, in_process, monkeypatch):
    ray, disk, hidden = two_nodes
    if not hidden:
        pytest.skip("unshare cannot make a mount namespace here")
    monkeypatch.chdir(disk)  # --out relative to the driver's working directory
    r = ok(invoke(*SWEEP, "--out", "sweep", "--workers", 2))
    text = " ".join(r.output.split())
    assert text.count(f"it ran where {disk / 'sweep'} is not, its files were written here") == 2
    _same_runs(disk / "sweep", in_process[0])
    # resumed on the nodes from the files the driver sends: as resumed in one process
    r = ok(invoke(*SWEEP, "--generations", 3, "--out", "sweep", "--workers", 2))
    assert "finished (2 done, 0 running, 0 failed of 2" in r.output
    _same_runs(disk / "sweep", in_process[1])


def test_sharded_evaluation_needs_no_shared_disk(two_nodes):
    ray, disk, hidden = two_nodes
    args = ["evolve", *SIZE, "--generations", 2, "--render-every", 0, "--budget", 400]
    ok(invoke(*args, "--logdir", disk / "one"))
    r = ok(invoke(*args, "--logdir", disk / "sharded", "--eval-workers", 2))
    assert "Evaluation: 2 shards on Ray actors" in r.output
    a, b = _only_run(disk / "one"), _only_run(disk / "sharded")
    assert (a / "teams.jsonl").read_bytes() == (b / "teams.jsonl").read_bytes()
    assert _summary(a) == _summary(b)
