"""Issue 37, points 1, 8 and 9: sweep tables that travel, and messages that say the one true thing.

- a folder of Parquet sweeps over different parameters read back with ``pd.read_parquet(DIR)`` or
  ``pyarrow.dataset.dataset(DIR)`` lost every column the first file lacked (``motion``: the two
  flexao rows could not be told apart);
- a user scenario's ``scenario`` column held the file's absolute path; ``fell`` was ``True`` in
  CSV where ``run --json`` says ``true``; ``task_load_max``, ``deadline_misses``, ``faults`` were
  JSON text inside cells; a column was named ``pic-mhz``; "1 runs";
- two tilt ranges were quoted (``-90..90`` by the parser, ``+-45`` by the platform); an unwritable
  place was reported as a full disk (and a sweep's ``--out`` there was a traceback); a misspelt
  scenario had no "did you mean"; a user scenario named by its ``name`` rather than its variable
  said only "has no 'nudge'".
"""

from __future__ import annotations

import csv
import shutil

import pytest
from helpers import REPO

from humanoid_twin.cli.main import main


def _main(argv: list[str], capsys) -> tuple[int, str, str]:
    try:
        rc = main(argv)
    except SystemExit as exc:
        rc = exc.code
    out, err = capsys.readouterr()
    return rc, out, err


@pytest.mark.slow
def test_a_folder_of_parquet_sweeps_over_different_parameters_reads_back_whole(tmp_path, capsys):
    pd = pytest.importorskip("pandas")
    ds = pytest.importorskip("pyarrow.dataset")
    folder = tmp_path / "sweeps"
    folder.mkdir()
    # the first file (by name) varies pic-mhz, the second motion: each must keep its own column
    rc, out, _ = _main(["sweep", "stand", "--param", "pic-mhz=5,40", "--duration", "3", "--no-progress",
                        "--out", str(folder / "a.parquet")], capsys)
    assert rc == 0 and "2 runs, 0 failed" in out
    rc, _, _ = _main(["sweep", "flexao", "--param", "motion=10,20", "--duration", "3", "--no-progress",
                      "--out", str(folder / "b.parquet")], capsys)
    assert rc == 0
    for df in (pd.read_parquet(folder), ds.dataset(folder, format="parquet").to_table().to_pandas()):
        rows = df.sort_values(["scenario", "motion", "pic_mhz"]).to_dict("records")
        assert len(rows) == 4
        assert [(r["scenario"], r["motion"]) for r in rows[:2]] == [("flexao", 10.0), ("flexao", 20.0)]
        assert [r["pic_mhz"] for r in rows[2:]] == [5.0, 40.0]
        assert pd.isna(rows[0]["pic_mhz"]) and pd.isna(rows[2]["motion"])
        # numbers, not JSON text: the slower clock loads the boards more
        assert rows[2]["task_load_max_slaves"] > rows[3]["task_load_max_slaves"] > 0
        assert all(r["deadline_misses_1"] == 0 and r["fell"] is False for r in rows)
        assert "pic-mhz" not in df.columns and "task_load_max" not in df.columns


@pytest.mark.slow
def test_a_csv_row_travels(tmp_path, capsys, monkeypatch):
    """One run of a user scenario, named relative to the current directory."""
    shutil.copy(REPO / "examples" / "push_recovery.py", tmp_path / "push.py")
    monkeypatch.chdir(tmp_path)
    rc, out, err = _main(["sweep", "push.py:gentle", "--param", "pic-mhz=40", "--duration", "3",
                          "--out", "t.csv"], capsys)
    assert rc == 0 and "t.csv: 1 run, 0 failed" in out and "1 run of push.py:gentle" in err
    with open(tmp_path / "t.csv", newline="") as f:
        (row,) = list(csv.DictReader(f))
    assert row["scenario"] == "push.py:gentle"        # as given: the table means the same elsewhere
    assert row["pic_mhz"] == "40" and "pic-mhz" not in row
    assert row["fell"] == "false" and row["completed"] == "false" and row["booted"] == "true"
    assert row["faults"] == "" and row["error"] == ""
    assert float(row["task_load_max_slaves"]) > 0 and row["deadline_misses_master"] == "0"
    assert not any(v.startswith(("{", "[")) for v in row.values())


@pytest.mark.parametrize("argv, message", [
    (["run", "stand", "--tilt", "100"], "--tilt 100: the platform tilts within +-45 degrees"),
    (["run", "stand", "--tilt", "60"], "--tilt 60: the platform tilts within +-45 degrees"),
    (["run", "stnad"], "did you mean stand?"),
    (["sweep", "levantar", "--param", "tilt=1", "--out", "t.csv"], "did you mean levantar_perna?"),
    (["run", "stand", "--duration", "3", "--out", "/proc/x.rrd"], "--out /proc/x.rrd: cannot write in /proc"),
    (["run", "stand", "--duration", "3", "--no-record", "--serial-log", "/proc/x.log"],
     "--serial-log /proc/x.log: cannot write in /proc"),
    (["sweep", "stand", "--duration", "3", "--out", "/proc/x.csv"],
     "--out /proc/x.csv: cannot write in /proc"),
    (["sweep", "stand", "--param", "tlt=1", "--out", "t.csv"], "did you mean tilt?"),
])
def test_messages_say_the_one_true_thing(argv, message, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    rc, out, err = _main(argv, capsys)
    assert rc == 2 and out == "" and message in err, err
    assert len(err.strip().splitlines()) == 1 and "-90..90" not in err and "MB free" not in err
    assert list(tmp_path.iterdir()) == []


NUDGE = """
from humanoid_twin.scenarios import REGISTRY, Scenario

soft = Scenario("nudge", REGISTRY["stand"].factory, moves=False, double_support=True)
"""


def test_a_user_scenario_named_by_its_name_says_which_variable(tmp_path, capsys, monkeypatch):
    (tmp_path / "user.py").write_text(NUDGE)
    monkeypatch.chdir(tmp_path)
    rc, _, err = _main(["run", "user.py:nudge", "--duration", "3"], capsys)
    assert rc == 2 and "'nudge' is the name of its Scenario object 'soft'" in err and "user.py:soft" in err
    rc, _, err = _main(["run", "user.py:sotf", "--duration", "3"], capsys)
    assert rc == 2 and "its Scenario objects: soft" in err and "did you mean soft?" in err
    assert not list(tmp_path.glob("*.rrd"))
