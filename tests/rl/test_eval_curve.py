"""`robot-hoi curve`: reading eval_curve.jsonl, the summary a comparison of runs is made from, and bad input."""

import json

import pytest

from robot_hoi.errors import UserError
from robot_hoi.rl.eval_curve import EVAL_CURVE_FILE, find_curves, read_curve, summarize, with_wall_time


def _row(step, success, duration, train_s, eval_s=2.0):
    return {"step": step, "samples": 6144 * step, "train_time_s": train_s, "eval_s": eval_s,
            "success_rate": success, "interaction_success_rate": 0.0, "duration_s": duration, "E_h_cm": 4.0,
            "E_o_max_cm": 9.0}


def _write(folder, rows):
    folder.mkdir(parents=True)
    (folder / EVAL_CURVE_FILE).write_text("".join(json.dumps(r) + "\n" for r in rows))
    return folder / EVAL_CURVE_FILE


def test_summary_first_success_best_and_late_mean(tmp_path):
    rows = [_row(25, 0.0, 2.0, 60), _row(50, 1.0, 6.6, 120), _row(75, 0.0, 3.0, 180), _row(100, 1.0, 6.6, 240),
            _row(125, 0.5, 5.0, 300)]
    s = summarize(rows, tail=3)
    assert s["first_full_success"]["step"] == 50 and s["first_full_success"]["wall_time_s"] == pytest.approx(124.0)
    assert s["best"]["step"] == 50  # ties keep the first, as the runner's model_best.pt does
    assert s["last"]["step"] == 125
    assert s["late_mean_success"] == pytest.approx(0.5) and s["late_mean_duration_s"] == pytest.approx(14.6 / 3)
    assert summarize([_row(25, 0.0, 2.0, 60)])["first_full_success"] is None
    tracked = {**_row(150, 1.0, 6.6, 360), "interaction_success_rate": 0.5}  # the object tracked too: ranks higher
    assert summarize(rows + [tracked])["best"]["step"] == 150
    assert [r["wall_time_s"] for r in with_wall_time(rows)] == [62.0, 124.0, 186.0, 248.0, 310.0]


def test_a_run_resumed_under_randomization_is_summarised_on_its_randomized_rows(tmp_path):
    nominal = [_row(25, 1.0, 6.6, 60), _row(50, 1.0, 6.6, 120)]
    randomized = [{**_row(75, 0.2, 4.0, 180), "validation": "training randomization"},
                  {**_row(100, 0.4, 4.5, 240), "validation": "training randomization"}]
    s = summarize(nominal + randomized, tail=3)
    assert s["best"]["step"] == 100 and s["first_full_success"] is None
    assert s["late_mean_success"] == pytest.approx(0.3) and s["late_evaluations"] == 2
    assert s["validation"] == "training randomization" and s["evaluations_validated_otherwise"] == 2
    assert summarize(nominal)["evaluations_validated_otherwise"] == 0


def test_runs_are_found_recursively_and_labelled_by_folder(tmp_path):
    _write(tmp_path / "a" / "out" / "box", [_row(25, 0.0, 2.0, 60)])
    _write(tmp_path / "b" / "out" / "box", [_row(25, 1.0, 6.6, 60), _row(50, 1.0, 6.6, 120)])
    curves = find_curves([str(tmp_path / "a"), str(tmp_path / "b" / "out" / "box" / EVAL_CURVE_FILE)])
    assert [c.label for c in curves] == [str(tmp_path / "a" / "out" / "box"), str(tmp_path / "b" / "out" / "box")]
    assert [len(c.rows) for c in curves] == [1, 2]


def test_bad_curves_name_the_file_and_the_problem(tmp_path):
    with pytest.raises(UserError, match="no such file or folder"):
        find_curves([str(tmp_path / "missing")])
    (tmp_path / "empty").mkdir()
    with pytest.raises(UserError, match=f"empty: no {EVAL_CURVE_FILE}"):
        find_curves([str(tmp_path / "empty")])
    path = _write(tmp_path / "bad", [_row(25, 0.0, 2.0, 60)])
    path.write_text(path.read_text() + "{not json\n")
    with pytest.raises(UserError, match=f"{EVAL_CURVE_FILE}: line 2 is not JSON"):
        read_curve(path)
    path.write_text(json.dumps({"step": 3}) + "\n")
    with pytest.raises(UserError, match="line 1 lacks samples, train_time_s"):
        read_curve(path)


def test_cli_prints_tables_and_summaries_and_writes_the_figure(tmp_path, capsys):
    from robot_hoi.cli import main

    _write(tmp_path / "run" / "box", [_row(25, 0.0, 2.0, 60), _row(50, 1.0, 6.6, 120)])
    figure = tmp_path / "curves.png"
    assert main(["curve", str(tmp_path / "run"), "--plot", str(figure)]) == 0
    out = capsys.readouterr().out
    assert "first success 1.00 at 2.0 min / 0.31 M" in out and "    50        2.0       2.1    0.31M" in out
    assert figure.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []  # no temp file left
    assert main(["curve", str(tmp_path / "run"), "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data[str(tmp_path / "run" / "box")]["summary"]["best"]["step"] == 50
    assert main(["curve", str(tmp_path / "run"), "--plot", str(tmp_path / "curves.txt")]) == 2
    assert "curves.txt: the figure must end in .png" in capsys.readouterr().err
