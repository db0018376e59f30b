"""tonguevis batch: the same results as the single-file commands, failures, resuming, loky and Dask runners.

A small generated corpus (three synthetic speakers, one five-syllable train
each) on the box tongue with 20 modes keeps these tests fast; segmentation
runs on the first production of each recording, validation without its
(slow) quasi-static baseline.
"""

from __future__ import annotations

import csv
import importlib.util
import json
import os
import shutil
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

pa = pytest.importorskip("pyarrow")
pq = pytest.importorskip("pyarrow.parquet")

from tests.analysis.energy_support import MODES, box_tongue  # noqa: E402
from tests.conftest import REPO, shared_file  # noqa: E402
from tonguevis.analysis.energy import CSV_COLUMNS  # noqa: E402
from tonguevis.batch import BatchSettings, run  # noqa: E402
from tonguevis.cli import main  # noqa: E402

FILES = ("spk1_ta.tsv", "spk2_ka.tsv", "spk3_la.tsv")
SETTINGS = dict(modes=MODES, landmarks="rule", segment_first=1, quasi_static=False)  # its baseline is slow
CLI_MODEL = ["--modes", str(MODES), "--landmarks", "rule", "--quiet"]
TABLES = ("simulation", "energy", "productions", "segmentation", "validation")


def _generator():
    spec = importlib.util.spec_from_file_location("make_demo_data", REPO / "scripts" / "make_demo_data.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def corpus(tmp_path_factory):
    """Three generated recordings (one train each) with their sensor map, as make_demo_data.py writes them."""
    from tonguevis.io import write_recording

    make = _generator()
    folder = tmp_path_factory.mktemp("corpus")
    for name in FILES:
        speaker, syllable = name[:-4].split("_")
        rec, _ = make.synthesize(speaker, syllable, n_trains=1)
        write_recording(rec, folder / name)
    (folder / "sensor_map.json").write_text(json.dumps(make.sensor_map_document()))
    return folder


@pytest.fixture(scope="module")
def serial(corpus, tmp_path_factory):
    """Every step, in this process, with CSV."""
    out = tmp_path_factory.mktemp("serial")
    result = run(corpus, out, model=box_tongue(), steps="simulate,energy,segment,validate", csv=True, **SETTINGS)
    assert result.ok and sorted(result.done) == sorted(FILES)
    return out


def _table(path):
    return pq.read_table(path).to_pydict()


def assert_same_tables(a, b, names=TABLES):
    """Equal corpus tables (timings aside)."""
    for name in names:
        ta, tb = _table(a / f"{name}.parquet"), _table(b / f"{name}.parquet")
        assert list(ta) == list(tb), name
        for column in ta:
            if column == "seconds":
                continue
            x, y = ta[column], tb[column]
            if x and isinstance(next((v for v in x if v is not None), ""), float):
                np.testing.assert_allclose(np.array(x, dtype=float), np.array(y, dtype=float), rtol=1e-12,
                                           atol=0, err_msg=f"{name}.{column}")
            else:
                assert x == y, f"{name}.{column}"


# ------------------------------------------------------------------ the same as the single-file commands
def test_energy_equals_tonguevis_energy(corpus, serial, tmp_path, monkeypatch):
    from tonguevis.cli import energy as energy_cli

    monkeypatch.setattr(energy_cli, "load_model", lambda args: box_tongue())
    out = tmp_path / "energy.csv"
    assert main(["energy", str(corpus), "--csv", str(out), *CLI_MODEL]) == 0
    assert (serial / "energy.csv").read_bytes() == out.read_bytes()
    # the Parquet table has the same columns, at full precision
    table = _table(serial / "energy.parquet")
    assert list(table) == list(CSV_COLUMNS)
    with open(out, newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == len(table["energy_J"]) > 0
    for column in ("time_s", "time_norm", "recording_time_s"):
        np.testing.assert_allclose(table[column], [float(r[column]) for r in rows], atol=5e-7)
    np.testing.assert_allclose(table["energy_J"], [float(r["energy_J"]) for r in rows], rtol=1e-8)
    for column in ("recording", "production", "speaker", "syllable"):
        assert table[column] == [r[column] for r in rows]
    for column in ("trial", "train", "index", "frame"):
        assert table[column] == [int(r[column]) for r in rows]
    productions = _table(serial / "productions.parquet")
    assert productions["production"] == ["1.2", "1.3", "1.4"] * 3
    assert productions["file"] == [f for f in FILES for _ in range(3)]


def test_motion_segmentation_validation_equal_the_commands(corpus, serial, tmp_path, monkeypatch):
    from tonguevis.analysis.segmentation import SegmentationResult
    from tonguevis.cli import segment as segment_cli
    from tonguevis.cli import simulate as simulate_cli
    from tonguevis.cli import validate as validate_cli
    from tonguevis.sim.motion import Motion

    monkeypatch.setattr(simulate_cli, "load_model_args", lambda args: box_tongue())
    monkeypatch.setattr(segment_cli, "load_model", lambda mesh, axes: box_tongue())
    monkeypatch.setattr(validate_cli, "load_model_args", lambda args: box_tongue())
    name = "spk2_ka"
    mine = serial / "recordings" / name
    recording = str(corpus / f"{name}.tsv")

    assert main(["simulate", recording, "--out", str(tmp_path / "sim"), *CLI_MODEL]) in (0, 1)
    theirs, ours = Motion.load(tmp_path / "sim" / "motion.npz"), Motion.load(mine / "motion.npz")
    for field in ("times", "q", "volume_change", "sensor_residual", "targets"):
        np.testing.assert_array_equal(getattr(ours, field), getattr(theirs, field), err_msg=field)
    # with the sensor humps the energy ½qᵀKq (K: the patches' full stiffness) differs in the last bit on half the
    # frames though q is bit-equal: equal to 1e-14
    np.testing.assert_allclose(ours.energy, theirs.energy, rtol=1e-14, atol=0, err_msg="energy")
    row = _table(mine / "simulation.parquet")
    assert row["peak_energy_mJ"][0] == pytest.approx(1e3 * ours.energy.max(), rel=1e-12)

    assert main(["segment", recording, "--production", "1", "--modes", str(MODES), "--landmarks", "rule",
                 "--out", str(tmp_path / "s.vtu"), "--save", str(tmp_path / "s.npz"), "--quiet"]) == 0
    expected = SegmentationResult.load(tmp_path / "s.npz")
    with np.load(mine / "segmentation.npz") as stored:
        np.testing.assert_array_equal(stored["labels"][0], expected.labels)
        assert stored["productions"].tolist() == [[1, 1, 2]]
    seg = _table(mine / "segmentation.parquet")
    assert seg["partitions"] == [expected.n_partitions] * expected.n_partitions
    assert seg["relative_error"][0] == pytest.approx(expected.relative_error, rel=1e-12)
    assert seg["tets"] == [r["tets"] for r in expected.partition_rows()]
    assert seg["seed_tet"] == [r["seed"] for r in expected.partition_rows()]

    assert main(["validate", recording, "--json", str(tmp_path / "v.json"), "--modes", str(MODES),
                 "--landmarks", "rule", "--no-static", "--quiet"]) == 0
    assert json.loads((mine / "validation.json").read_text()) == json.loads((tmp_path / "v.json").read_text())
    val = _table(mine / "validation.parquet")
    document = json.loads((tmp_path / "v.json").read_text())
    assert val["sensor"] == list(document["sensors"])
    assert val["model_rmse_mm"] == [s["model_rmse_mm"] for s in document["sensors"].values()]


# ------------------------------------------------------------------ parallel runners
def test_two_loky_workers_give_the_same_tables(corpus, serial, tmp_path):
    result = run(corpus, tmp_path, workers=2, model=box_tongue(), steps="simulate,energy,segment,validate",
                 **SETTINGS)
    assert result.ok and len(result.done) == 3
    assert os.getpid() not in result.workers and 1 <= len(result.workers) <= 2
    assert all(rss > 0 for rss in result.workers.values())
    assert_same_tables(serial, tmp_path)


def test_dask_local_cluster_gives_the_same_tables(corpus, serial, tmp_path):
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False,
                                  dashboard_address=None) as cluster, distributed.Client(cluster) as client:
        result = run(corpus, tmp_path, workers=client, model=box_tongue(),
                     steps="simulate,energy,segment,validate", **SETTINGS)
    assert result.ok and len(result.done) == 3
    assert json.loads((tmp_path / "batch.json").read_text())["runner"] == "dask"
    assert_same_tables(serial, tmp_path)


# ------------------------------------------------------------------ failures
def test_a_bad_file_among_good_ones(corpus, tmp_path, monkeypatch, capsys):
    from tonguevis.cli import batch as batch_cli

    folder = tmp_path / "corpus"
    folder.mkdir()
    for name in ("spk1_ta.tsv", "spk1_ta.wav", "spk2_ka.tsv", "spk2_ka.wav", "sensor_map.json"):
        shutil.copy(corpus / name, folder / name)
    (folder / "spk9_ta.tsv").write_text("this is not an NDI Wave export\n1\t2\n")
    monkeypatch.setattr(batch_cli, "load_model", lambda args: box_tongue())
    out = tmp_path / "out"
    code = main(["batch", str(folder), "--out", str(out), "--steps", "simulate,energy", *CLI_MODEL])
    printed = capsys.readouterr().out.splitlines()
    assert code == 1
    assert printed[-1].startswith("batch: 3 recordings") and "2 done, 1 failed" in printed[-1]
    assert any(line.startswith("failed: spk9_ta.tsv (open): ") for line in printed)
    with open(out / "failures.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert [(r["file"], r["step"]) for r in rows] == [("spk9_ta.tsv", "open")]
    assert "spk9_ta.tsv" in rows[0]["error"]
    assert sorted(set(_table(out / "energy.parquet")["recording"])) == ["spk1_ta", "spk2_ka"]
    manifest = json.loads((out / "recordings" / "spk9_ta" / "manifest.json").read_text())
    assert manifest["failure"]["step"] == "open" and manifest["steps"] == {}
    # all good: status 0, the failure list is empty; the bad file alone is retried
    (folder / "spk9_ta.tsv").unlink()
    assert main(["batch", str(folder), "--out", str(out), "--steps", "simulate,energy", *CLI_MODEL]) == 0
    assert "0 done, 2 up to date, 0 failed" in capsys.readouterr().out
    assert (out / "failures.csv").read_text().strip() == "file,step,error"


def test_a_failing_step_keeps_the_steps_before_it(corpus, tmp_path, monkeypatch):
    from tonguevis.batch import tasks

    def broken(*args):
        raise RuntimeError("no room left")

    monkeypatch.setitem(tasks._STEPS, "segment", broken)
    result = run(corpus / "spk1_ta.tsv", tmp_path, model=box_tongue(), **SETTINGS)
    assert result.failures == [("spk1_ta.tsv", "segment", "RuntimeError: no room left")]
    manifest = json.loads((tmp_path / "recordings" / "spk1_ta" / "manifest.json").read_text())
    assert sorted(manifest["steps"]) == ["energy", "simulate"]
    assert "Traceback" in manifest["failure"]["traceback"]
    assert len(_table(tmp_path / "energy.parquet")["energy_J"]) > 0
    assert len(_table(tmp_path / "segmentation.parquet")["partition"]) == 0


# ------------------------------------------------------------------ resuming
def _counting(monkeypatch):
    """Count the steps run (and the simulations) per recording."""
    from tonguevis.batch import tasks
    from tonguevis.workflows import simulate_recording

    calls = []
    for step, function in list(tasks._STEPS.items()):
        def counted(task, *args, _f=function, _s=step):
            calls.append((task.file, _s))
            return _f(task, *args)
        monkeypatch.setitem(tasks._STEPS, step, counted)

    def simulating(rec, *args, **kwargs):
        calls.append((rec.metadata["file"].split(os.sep)[-1], "simulation"))
        return simulate_recording(rec, *args, **kwargs)

    monkeypatch.setattr("tonguevis.workflows.simulate_recording", simulating)
    return calls


def test_resume_after_an_interruption(corpus, tmp_path, monkeypatch):
    from tonguevis.batch import tasks

    folder = tmp_path / "corpus"
    shutil.copytree(corpus, folder)
    out = tmp_path / "out"
    energy = tasks._STEPS["energy"]

    def interrupted(task, *args):
        if task.file == "spk2_ka.tsv":
            raise KeyboardInterrupt
        return energy(task, *args)

    with monkeypatch.context() as patch:
        patch.setitem(tasks._STEPS, "energy", interrupted)
        with pytest.raises(KeyboardInterrupt):
            run(folder, out, model=box_tongue(), **SETTINGS)
    # the first recording is complete, the second has its motion, the third nothing
    assert sorted(json.loads((out / "recordings" / "spk1_ta" / "manifest.json").read_text())["steps"]) == [
        "energy", "segment", "simulate"]
    assert (out / "recordings" / "spk2_ka" / "motion.npz").is_file()
    assert not (out / "recordings" / "spk3_la").exists()

    calls = _counting(monkeypatch)
    result = run(folder, out, model=box_tongue(), **SETTINGS)
    assert result.ok and result.up_to_date == ["spk1_ta.tsv"] and result.done == ["spk2_ka.tsv", "spk3_la.tsv"]
    # spk2's saved motion is reused: it is not simulated again
    assert calls == [("spk2_ka.tsv", "energy"), ("spk2_ka.tsv", "segment"), ("spk3_la.tsv", "simulation"),
                     ("spk3_la.tsv", "simulate"), ("spk3_la.tsv", "energy"), ("spk3_la.tsv", "segment")]
    fresh = tmp_path / "fresh"
    run(folder, fresh, model=box_tongue(), **SETTINGS)
    assert_same_tables(fresh, out, ("simulation", "energy", "productions", "segmentation"))

    # touching a file changes nothing (content hashes, not times) ...
    calls.clear()
    os.utime(folder / "spk1_ta.tsv")
    assert run(folder, out, model=box_tongue(), **SETTINGS).up_to_date == list(FILES)
    assert calls == []
    # ... a new segmentation setting redoes the segmentation only, from the saved motions ...
    settings = BatchSettings(**{**SETTINGS, "segment_first": 2})
    assert run(folder, out, model=box_tongue(), settings=settings).done == list(FILES)
    assert calls == [(f, "segment") for f in FILES]
    assert len(set(_table(out / "segmentation.parquet")["production"])) == 2
    # ... and new content redoes that recording
    calls.clear()
    shutil.copy(folder / "spk3_la.tsv", folder / "spk1_ta.tsv")
    result = run(folder, out, model=box_tongue(), settings=settings)
    assert result.done == ["spk1_ta.tsv"] and {c[0] for c in calls} == {"spk1_ta.tsv"}


def test_killed_run_resumes(corpus, tmp_path):
    """SIGKILL after the first recording: what was finished is kept, nothing half-written counts."""
    out = tmp_path / "out"
    script = ("import sys, time\n"
              "from tests.analysis.energy_support import box_tongue\n"
              "from tonguevis.batch import run, tasks\n"
              "simulate = tasks._STEPS['simulate']\n"
              "def slow(task, *args):  # the second recording is in flight when the first is done\n"
              "    if task.file != 'spk1_ta.tsv':\n"
              "        time.sleep(30)\n"
              "    return simulate(task, *args)\n"
              "tasks._STEPS['simulate'] = slow\n"
              f"run(sys.argv[1], sys.argv[2], model=box_tongue(), modes={MODES}, landmarks='rule', segment_first=3)\n")
    log = tmp_path / "child.log"
    with open(log, "w") as fh:
        child = subprocess.Popen([sys.executable, "-c", script, str(corpus), str(out)], cwd=REPO,
                                 env=dict(os.environ), stdout=fh, stderr=subprocess.STDOUT)
    first = out / "recordings" / "spk1_ta" / "manifest.json"
    deadline = time.monotonic() + 120
    try:
        while time.monotonic() < deadline and child.poll() is None:
            if first.is_file() and "segment" in json.loads(first.read_text())["steps"]:
                break
            time.sleep(0.05)
    finally:
        ended = child.poll()
        child.send_signal(signal.SIGKILL)
        child.wait()
    assert ended is None, f"the batch ended on its own ({ended}): {log.read_text()[-2000:]}"
    assert first.is_file() and not (out / "energy.parquet").exists()
    (first.parent / ".energy.parquet.x1y2.tmp.parquet").write_bytes(b"PAR1 cut short")  # as a kill mid-write leaves
    result = run(corpus, out, model=box_tongue(), modes=MODES, landmarks="rule", segment_first=3)
    assert result.ok and "spk1_ta.tsv" in result.up_to_date and len(result.up_to_date) + len(result.done) == 3
    assert not list(out.rglob(".*.tmp*"))  # a temporary file the kill left is removed
    fresh = tmp_path / "fresh"
    run(corpus, fresh, model=box_tongue(), modes=MODES, landmarks="rule", segment_first=3)
    assert_same_tables(fresh, out, ("simulation", "energy", "productions", "segmentation"))


# ------------------------------------------------------------------ CLI and real recordings
def test_cli_help_and_bad_settings(tmp_path, capsys):
    with pytest.raises(SystemExit):
        main(["batch", "--help"])
    text = capsys.readouterr().out
    for option in ("--jobs", "--scheduler", "--steps", "--csv", "--sensor-stiffness", "--modes", "--rest", "--mesh"):
        assert option in text
    assert main(["batch", str(tmp_path), "--out", str(tmp_path / "o"), "--steps", "simulate,dance"]) == 2
    assert "unknown step(s) dance" in capsys.readouterr().err
    assert main(["batch", str(tmp_path), "--out", str(tmp_path / "o")]) == 2
    assert "no recordings found" in capsys.readouterr().err


def test_real_recordings(tmp_path):
    """The real Opti-Speech /ta/ and /ka/ and the Haskins sentence simulate and give curves; a format-test
    file without tongue channels is a failure that names the problem."""
    files = [shared_file("ema", "optispeech", "009_OSN12_Tah_withFb_natural_HR.tsv"),
             shared_file("ema", "optispeech", "006_OSN12_Kah_nofb_natural_take2_HR.tsv"),
             shared_file("ema", "mview", "F01_B01_S01_R01_N.mat"),
             shared_file("ema", "carstens", "artk_ag500.pos")]
    result = run(files, tmp_path, steps="simulate,energy", modes=40)
    assert [(f, step) for f, step, _ in result.failures] == [("carstens/artk_ag500.pos", "simulate")]
    assert "tongue sensors" in result.failures[0][2]
    simulation = _table(tmp_path / "simulation.parquet")
    assert simulation["file"] == ["optispeech/009_OSN12_Tah_withFb_natural_HR.tsv",
                                  "optispeech/006_OSN12_Kah_nofb_natural_take2_HR.tsv", "mview/F01_B01_S01_R01_N.mat"]
    assert all(rest in ("detected", "stillest window") for rest in simulation["rest_how"])
    recordings = set(_table(tmp_path / "energy.parquet")["recording"])
    assert {"006_OSN12_Kah_nofb_natural_take2_HR", "009_OSN12_Tah_withFb_natural_HR"} <= recordings


def test_generator_makes_more_speakers(tmp_path):
    """make_demo_data.py --speakers N: speakers beyond the demo three have their own habits, and their
    productions are found where the generator put them."""
    from tonguevis.preprocess import find_productions
    from tonguevis.workflows import head_corrected, open_recording
    from tonguevis.io import write_recording

    make = _generator()
    names = make.speaker_names(6)
    assert names == [f"spk{k}" for k in range(1, 7)]
    assert make.SPEAKERS["spk5"] == make.generated_speaker(5) != make.generated_speaker(6)
    rec, truth = make.synthesize("spk5", "ka", n_trains=2)
    write_recording(rec, tmp_path / "spk5_ka.tsv")
    (tmp_path / "sensor_map.json").write_text(json.dumps(make.sensor_map_document()))
    table = find_productions(head_corrected(open_recording(tmp_path / "spk5_ka.tsv")), keep=None)
    assert len(table) == len(truth["productions"]) == 10
    np.testing.assert_allclose(table.as_array()[:, 2], [p["start"] for p in truth["productions"]], atol=0.03)
