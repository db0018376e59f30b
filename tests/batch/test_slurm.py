"""tonguevis batch --slurm: the same tables as one local process, job ids, jobs that die, the resume.

The tests marked ``slurm`` submit real SLURM jobs (dask-jobqueue) to the SLURM running on this
machine (``scripts/slurm_local.sh start``; ``.ci/run`` starts it) and skip, saying why, where none
is running.  They run eight recordings of the demo corpus (``data/``) on the box tongue of the
other batch tests, in two one-core jobs; the scheduler runs in this test process and the workers
reach it on the loopback interface.  The others check the options and run everywhere.
"""

from __future__ import annotations

import csv
import importlib.util
import json
import shutil
import subprocess
import threading
import time
from pathlib import Path

import numpy as np
import pytest

pq = pytest.importorskip("pyarrow.parquet")

from tests.analysis.energy_support import MODES, box_tongue  # noqa: E402
from tonguevis.cli import main  # noqa: E402
from tonguevis.paths import DATA_DIR  # noqa: E402

FILES = [f"spk{s}_{y}.tsv" for s in (1, 2) for y in ("ta", "ka", "la", "ra")]
# every step; validation without its slow quasi-static baseline; every production segmented, so that a
# recording is in flight long enough (~1 s) to cancel its job under it
COMMAND = ["--steps", "simulate,energy,segment,validate", "--no-static", "--csv", "--modes", str(MODES),
           "--landmarks", "rule"]
#: Tables with a wall-time column ("seconds"): byte for byte equal but for it; the others as files.
TIMED = ("simulation", "segmentation")
UNTIMED = ("energy", "productions", "validation")
PROFILE = """\
# the workers of these tests: one core, a little memory, on this machine's loopback
[slurm]
cores = 1
memory = "1GB"
walltime = "00:10:00"
interface = "lo"
"""


def slurm_missing() -> str | None:
    """Why the batch cannot run on SLURM here, or None."""
    if importlib.util.find_spec("dask_jobqueue") is None:
        return "dask-jobqueue is not installed (pip install -e '.[batch]')"
    if shutil.which("sbatch") is None or shutil.which("sinfo") is None:
        return "SLURM is not installed here (scripts/slurm_local.sh start installs and starts it)"
    try:
        run = subprocess.run(["sinfo", "--noheader", "--format=%T"], capture_output=True, text=True, timeout=20)
    except subprocess.TimeoutExpired:
        return "sinfo did not answer: slurmctld is not running (scripts/slurm_local.sh start)"
    if run.returncode != 0:
        return f"SLURM is not running ({' '.join(run.stderr.split())}): scripts/slurm_local.sh start"
    if not any(state.startswith(("idle", "mixed", "allocated")) for state in run.stdout.split()):
        return f"no SLURM node is up (sinfo: {', '.join(run.stdout.split()) or 'no node'})"
    return None


@pytest.fixture(scope="module")
def slurm():
    why = slurm_missing()
    if why:
        pytest.skip(why)


@pytest.fixture
def box_model(monkeypatch):
    from tonguevis.cli import batch as batch_cli

    monkeypatch.setattr(batch_cli, "load_model", lambda args: box_tongue())


@pytest.fixture(scope="module")
def profile(tmp_path_factory):
    path = tmp_path_factory.mktemp("profile") / "slurm.toml"
    path.write_text(PROFILE)
    return path


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """The eight recordings in this process (``--jobs 1``)."""
    from tonguevis.cli import batch as batch_cli

    out = tmp_path_factory.mktemp("reference")
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(batch_cli, "load_model", lambda args: box_tongue())
        assert main(["batch", *demo_files(), "--out", str(out), "--jobs", "1", *COMMAND, "--quiet"]) == 0
    return out


def demo_files() -> list[str]:
    return [str(DATA_DIR / name) for name in FILES]


def slurm_command(out, profile, *more) -> list[str]:
    return ["batch", *demo_files(), "--out", str(out), "--slurm", "--slurm-jobs", "2", "--slurm-profile",
            str(profile), *COMMAND, *more]


def assert_same_tables(a, b):
    """Byte for byte: every CSV and Parquet file of the tables without wall times; the others' columns but
    "seconds" (the wall time of a step, which no two runs share), value for value."""
    for name in UNTIMED:
        for suffix in (".parquet", ".csv"):
            assert (a / f"{name}{suffix}").read_bytes() == (b / f"{name}{suffix}").read_bytes(), name + suffix
    for name in TIMED:
        ta, tb = pq.read_table(a / f"{name}.parquet"), pq.read_table(b / f"{name}.parquet")
        assert ta.schema == tb.schema and ta.num_rows == tb.num_rows > 0, name
        ta, tb = ta.drop_columns(["seconds"]).to_pydict(), tb.drop_columns(["seconds"]).to_pydict()
        for column in ta:  # floats to 1e-12: with the sensor humps the patch shapes' last bits follow the BLAS
            x, y = ta[column], tb[column]  # threads of the process (a SLURM job's against the command's)
            if x and isinstance(next((v for v in x if v is not None), ""), float):
                np.testing.assert_allclose(np.array(x, dtype=float), np.array(y, dtype=float), rtol=1e-12, atol=0,
                                           err_msg=f"{name}.{column}")
            else:
                assert x == y, f"{name}.{column}"


def manifest(out, file) -> dict:
    return json.loads((out / "recordings" / file.removesuffix(".tsv") / "manifest.json").read_text())


def batch_document(out) -> dict:
    return json.loads((out / "batch.json").read_text())


def in_flight(out, done_step="simulate", last_step="validate"):
    """{file: SLURM job} of the recordings a worker is running now (its manifest has its first step, not its last)."""
    running = {}
    for file in FILES:
        try:
            m = manifest(out, file)
        except (OSError, ValueError):
            continue
        if done_step in m.get("steps", {}) and last_step not in m["steps"] and m.get("slurm_job"):
            running[file] = m["slurm_job"]
    return running


def cancel_when_in_flight(out, how_many: int, log: list) -> threading.Thread:
    """A thread that, as soon as recordings are in flight on ``how_many`` SLURM jobs, cancels those jobs."""
    def watch():
        deadline = time.monotonic() + 240
        while time.monotonic() < deadline:
            jobs = sorted(set(in_flight(out).values()))
            if len(jobs) >= how_many:
                log.extend(jobs[:how_many])
                subprocess.run(["scancel", *jobs[:how_many]], check=True)
                return
            time.sleep(0.02)

    thread = threading.Thread(target=watch, daemon=True)
    thread.start()
    return thread


# ------------------------------------------------------------------ on SLURM
@pytest.mark.slurm
def test_two_slurm_jobs_give_the_same_tables_as_one_process(slurm, reference, profile, box_model, tmp_path, capsys):
    out = tmp_path / "out"
    assert main(slurm_command(out, profile)) == 0
    said = capsys.readouterr()
    assert "batch: 8 recordings" in said.out and "8 done, 0 failed" in said.out
    assert_same_tables(reference, out)

    # the job ids: in batch.json (state, node, what each ran) and in every recording's manifest
    document = batch_document(out)
    assert document["runner"] == "slurm, 2 jobs of 1 one-thread worker(s)"
    jobs = document["slurm"]["jobs"]
    assert len(jobs) == 2 and document["slurm"]["version"].startswith("slurm")
    assert sorted(f for job in jobs.values() for f in job["recordings"]) == sorted(FILES)
    for job_id, job in jobs.items():
        assert job["state"] == "RUNNING" and job["lost"] == []
        for file in job["recordings"]:
            assert manifest(out, file)["slurm_job"] == job_id
    assert document["slurm"]["options"]["interface"] == "lo" and document["slurm"]["options"]["jobs"] == 2
    # the jobs' logs, and their starts and ends as they happened
    assert {p.name for p in (out / "slurm").iterdir()} >= {f"tonguevis-batch-{j}.err" for j in jobs}
    for job_id in jobs:
        assert f"batch: SLURM job {job_id} submitted" in said.err
        assert f"batch: SLURM job {job_id} running on " in said.err
        assert f"batch: SLURM job {job_id} released after {len(jobs[job_id]['recordings'])} recording(s)" in said.err
    # nothing left in the queue (cancelled when the batch ended; "completing" for a moment)
    deadline, queued = time.monotonic() + 60, "?"
    while queued and time.monotonic() < deadline:
        queued = subprocess.run(["squeue", "--noheader", f"--jobs={','.join(jobs)}"], capture_output=True,
                                text=True).stdout.strip()
        time.sleep(0.5)
    assert queued == ""


@pytest.mark.slurm
def test_a_cancelled_job_loses_its_recording_in_flight_and_the_rerun_completes(slurm, reference, profile, box_model,
                                                                               tmp_path, capsys):
    out = tmp_path / "out"
    cancelled: list[str] = []
    watcher = cancel_when_in_flight(out, 1, cancelled)
    assert main(slurm_command(out, profile)) == 1
    watcher.join(5)
    said = capsys.readouterr()
    assert len(cancelled) == 1, said
    job = cancelled[0]

    document = batch_document(out)
    jobs = document["slurm"]["jobs"]
    assert jobs[job]["state"] == "CANCELLED"
    lost = jobs[job]["lost"]
    assert len(lost) == 1  # one one-thread worker per job: one recording in flight
    (other,) = set(jobs) - {job}
    assert jobs[other]["state"] == "RUNNING" and jobs[other]["lost"] == []
    # the others all done, by either job; the lost one is said, with how to resume
    assert sorted(jobs[job]["recordings"] + jobs[other]["recordings"] + lost) == sorted(FILES)
    assert f"lost: {lost[0]}: lost with SLURM job {job} (CANCELLED); run the same command again to resume" in said.out
    assert "7 done, 0 failed, 1 lost with their SLURM job (run the same command again to resume)" in said.out
    assert f"batch: SLURM job {job} ended: CANCELLED" in said.err and f"lost: {lost[0]}" in said.err
    with open(out / "failures.csv", newline="") as fh:
        assert [(r["file"], r["step"]) for r in csv.DictReader(fh)] == [(lost[0], "lost")]
    assert "validate" not in manifest(out, lost[0])["steps"]

    # the same command again does the lost recording only, and the tables are those of one process
    assert main(slurm_command(out, profile)) == 0
    assert "1 done, 7 up to date, 0 failed" in capsys.readouterr().out
    assert (out / "failures.csv").read_text().strip() == "file,step,error"
    assert_same_tables(reference, out)


@pytest.mark.slurm
def test_when_every_job_ends_the_batch_stops_and_the_rerun_completes(slurm, reference, profile, box_model, tmp_path,
                                                                     capsys):
    """As when the jobs reach their walltime together: what was in flight is lost, what was not started is
    said, and the batch returns instead of waiting for workers that will not come."""
    out = tmp_path / "out"
    cancelled: list[str] = []
    watcher = cancel_when_in_flight(out, 2, cancelled)
    started = time.monotonic()
    assert main(slurm_command(out, profile)) == 1
    watcher.join(5)
    assert time.monotonic() - started < 120
    said = capsys.readouterr()
    assert len(cancelled) == 2, said
    jobs = batch_document(out)["slurm"]["jobs"]
    assert {j["state"] for j in jobs.values()} == {"CANCELLED"}
    with open(out / "failures.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert rows and {r["step"] for r in rows} == {"lost"}
    in_flight_lost = sorted(f for j in jobs.values() for f in j["lost"])
    assert len(in_flight_lost) == 2
    not_started = [r["file"] for r in rows if r["file"] not in in_flight_lost]
    assert all("not started: every SLURM job of the batch has ended" in r["error"] for r in rows
               if r["file"] in not_started)
    done = [f for j in jobs.values() for f in j["recordings"]]
    assert sorted(done + [r["file"] for r in rows]) == sorted(FILES)

    assert main(slurm_command(out, profile)) == 0
    up_to_date = f", {len(done)} up to date" if done else ""
    assert f"{len(rows)} done{up_to_date}, 0 failed" in capsys.readouterr().out
    assert_same_tables(reference, out)


@pytest.mark.slurm
def test_a_job_slurm_refuses_is_one_clear_error(slurm, profile, tmp_path, capsys):
    code = main(["batch", *demo_files(), "--out", str(tmp_path / "out"), "--slurm", "--slurm-profile", str(profile),
                 "--slurm-queue", "no-such-partition", "--quiet"])
    err = capsys.readouterr().err
    assert code == 2
    assert "SLURM refuses the workers' job: invalid partition specified: no-such-partition" in err


# ------------------------------------------------------------------ the options, anywhere
def test_profile_and_options(tmp_path):
    pytest.importorskip("dask")
    from tonguevis.batch import BatchError
    from tonguevis.batch.slurm import SlurmOptions

    path = tmp_path / "lab.toml"
    path.write_text('[slurm]\njobs = 12\ncores = 8\nmemory = "8GB"\nqueue = "compute"\naccount = "my-lab"\n'
                    'prologue = ["module load python/3.11"]\n')
    options = SlurmOptions.from_profile(path, jobs=2, walltime=None)
    assert (options.jobs, options.cores, options.memory, options.queue, options.account) == (
        2, 8, "8GB", "compute", "my-lab")
    assert options.walltime == "01:00:00" and options.prologue == ("module load python/3.11",)

    for text, error in (('[slurm]\njobs = 2\nnodes = 3\n', r"lab.toml: unknown key\(s\) nodes in \[slurm\]"),
                        ('[slurm]\nwalltime = "two hours"\n', "lab.toml: SLURM walltime must be like '02:00:00'"),
                        ('[cluster]\njobs = 2\n', r"lab.toml: no \[slurm\] table"),
                        ('[slurm\n', "lab.toml: not TOML")):
        path.write_text(text)
        with pytest.raises(BatchError, match=error):
            SlurmOptions.from_profile(path)
    with pytest.raises(BatchError, match="cannot read the SLURM profile"):
        SlurmOptions.from_profile(tmp_path / "nowhere.toml")
    for bad in ({"jobs": 0}, {"cores": 1.5}, {"memory": "lots"}, {"walltime": "1h"}):
        with pytest.raises(BatchError, match="SLURM"):
            SlurmOptions(**bad)
    for fine in ("30", "1:30", "02:00:00", "1-12", "1-12:00:00"):
        assert SlurmOptions(walltime=fine).walltime == fine


def test_cli_slurm_options(tmp_path, capsys, monkeypatch):
    pytest.importorskip("dask_jobqueue")
    with pytest.raises(SystemExit):
        main(["batch", "--help"])
    text = capsys.readouterr().out
    for option in ("--slurm", "--slurm-jobs", "--slurm-cores", "--slurm-memory", "--slurm-walltime", "--slurm-queue",
                   "--slurm-account", "--slurm-profile"):
        assert option in text
    corpus = [str(DATA_DIR / "spk1_ta.tsv")]
    assert main(["batch", *corpus, "--out", str(tmp_path / "o"), "--slurm-jobs", "2"]) == 2
    assert "--slurm-jobs without --slurm" in capsys.readouterr().err
    with pytest.raises(SystemExit):  # one place to run: --jobs, --scheduler or --slurm
        main(["batch", *corpus, "--out", str(tmp_path / "o"), "--slurm", "--jobs", "2"])
    assert "not allowed with argument" in capsys.readouterr().err
    monkeypatch.setenv("PATH", str(tmp_path))  # no sbatch
    assert main(["batch", *corpus, "--out", str(tmp_path / "o"), "--slurm", "--modes", str(MODES)]) == 2
    assert "--slurm needs SLURM's commands (sbatch, squeue)" in capsys.readouterr().err


def test_job_of_a_worker():
    """dask-jobqueue names a job's workers after the job: NAME with one worker per job, NAME-k with more."""
    from types import SimpleNamespace

    from tonguevis.batch.slurm_jobs import JobWatch

    cluster = SimpleNamespace(workers={"SLURMCluster-0": SimpleNamespace(job_id="41"),
                                       "SLURMCluster-1": SimpleNamespace(job_id="42")})
    client = SimpleNamespace(scheduler_info=lambda: {"workers": {}})
    said = []
    watch = JobWatch(cluster, client, Path("logs"), notify=said.append, every=1e9)
    watch._squeue = lambda: None  # no SLURM here
    assert watch.poll() is None
    assert said == ["SLURM job 41 submitted (tonguevis-batch)", "SLURM job 42 submitted (tonguevis-batch)"]
    assert watch.job_of("SLURMCluster-0") == "41" and watch.job_of("SLURMCluster-1-3") == "42"
    assert watch.job_of("SLURMCluster-7") is None and watch.job_of(None) is None
    cluster.workers.clear()  # the jobs are gone; their names still map
    assert watch.job_of("SLURMCluster-1") == "42"


def test_the_batch_stops_only_when_slurm_says_every_job_ended(monkeypatch):
    """No worker and SLURM not answering is not an end (the jobs may be waiting); SLURM forgetting them is."""
    from types import SimpleNamespace

    from tonguevis.batch import slurm_jobs

    cluster = SimpleNamespace(workers={"SLURMCluster-0": SimpleNamespace(job_id="41")})
    client = SimpleNamespace(scheduler_info=lambda: {"workers": {}})
    said = []
    watch = slurm_jobs.JobWatch(cluster, client, Path("logs"), notify=said.append, every=0.0)
    answers = iter([None, {"41": ("PENDING", "", "Priority")}, None, {"41": ("TIMEOUT", "node7", "")}])
    monkeypatch.setattr(slurm_jobs, "squeue", lambda ids: next(answers))
    assert watch.poll() is None and watch.jobs["41"].state == "PENDING"  # no answer: nothing known
    assert watch.poll() is None and said[-1] == "SLURM job 41 pending (Priority)"
    assert watch.poll() is None
    assert watch.poll() == "every SLURM job of the batch has ended (41: TIMEOUT)"
    assert said[-1] == "SLURM job 41 ended: TIMEOUT on node7 after 0 recording(s)"
