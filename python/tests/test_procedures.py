"""The paper's procedures and the workflow: the same results as the CLI's --json."""

import json
import subprocess

import numpy as np
import pandas as pd
import pytest

from backdrive_rig import BadValueError, Rig, RigError, compare, design, discover, explain

from conftest import rig_cli


def cli_json(*args):
    out = subprocess.run([rig_cli(), *args], capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout)


def test_design_is_rig_design_json():
    assert design(z=[49, 51, 50, 50]) == cli_json("design", "--z", "49,51,50,50", "--json")
    r = design(z=[50, 50, 51, 49], eta_gross=0.423)
    assert r == cli_json("design", "--z", "50,50,51,49", "--eta-gross", "0.423", "--json")
    # Table 1 (rig-facts): rho 25.5 ... -7.84, mu_s Lambda 1.336 / 0.668 / 0.445.
    t1 = design(table1=True)
    assert t1 == cli_json("design", "--table1", "--json")
    assert [round(d.rho, 2) for d in t1] == [25.5, -24.5, 13.0, -12.0, 8.84, -7.84]
    assert [round(d.mu_s_lambda, 3) for d in t1] == [1.336, 1.336, 0.668, 0.668, 0.445, 0.445]
    assert r.mu_from_eta == pytest.approx(0.271, abs=5e-4)


def test_design_refuses_bad_input_naming_it():
    with pytest.raises(BadValueError, match="49, 51, 50, 49|invalid gear set"):
        design(z=[49, 51, 50, 49])
    with pytest.raises(BadValueError, match="pressure_angle_deg 50"):
        design(pressure_angle_deg=50)
    with pytest.raises(BadValueError, match="unknown option"):
        design(teeth=[1, 2, 3, 4])
    with pytest.raises(BadValueError, match="table1"):
        design(z=[49, 51, 50, 50], table1=True)


@pytest.fixture(scope="module")
def sim_sweep_csv(tmp_path_factory):
    """`rig sim torque-sweep`'s CSV (Figs. 8-9 on the virtual rig, in virtual time)."""
    csv = tmp_path_factory.mktemp("sim") / "sweep.csv"
    sim = subprocess.run(
        [rig_cli(), "sim", "torque-sweep", "--csv", str(csv)], capture_output=True, text=True, timeout=600
    )
    assert sim.returncode == 0, sim.stderr
    return csv


def test_explain_on_a_csv_is_rig_explain_json(sim_sweep_csv, tmp_path):
    csv = sim_sweep_csv
    ours = explain(csv, replicates=20)
    cli = cli_json("explain", "--measured", str(csv), "--json", "--no-report", "--replicates", "20")
    for key in ("verdict", "effects", "rmse_before_a", "rmse_after_a", "lack_of_fit"):
        assert ours[key] == cli[key], key
    with pytest.raises(BadValueError, match="alpha 0.7"):
        explain(csv, alpha=0.7)
    # A proposal on request, as `rig explain --propose`: the same keys, and its plan text.
    proposed = explain(csv, replicates=20, propose=True)
    cli_p = cli_json(
        "explain", "--measured", str(csv), "--json", "--no-report", "--replicates", "20",
        "--propose", str(tmp_path / "next.toml"),
    )["proposal"]
    assert set(proposed.proposal) - {"plan_toml"} == set(cli_p)
    assert proposed.proposal["plan_written"] is None
    plan_text = proposed.proposal["plan_toml"]
    assert "[[points]]" in plan_text or "points" in plan_text
    with Rig.virtual(speed=10) as rig:
        # The plan parses (the refusal that follows is the live release, checked after it).
        with rig.release(freq_hz=10, seconds=30):
            with pytest.raises(BadValueError, match="release is live"):
                rig.torque_sweep(plan_toml=plan_text)
        with pytest.raises(RigError, match="plan_toml"):
            rig.torque_sweep(plan_toml="[[points]]\nload_nm = 'heavy'\n")


def test_compare_is_rig_compare_json(sim_sweep_csv, tmp_path):
    csv = sim_sweep_csv
    ours = compare(csv)
    cli = cli_json("compare", "--measured", str(csv), "--json")
    assert set(ours) == set(cli)
    assert ours.gap_rmse_base_a == cli["gap_rmse_base_a"]
    assert ours.gap_rmse_model_a is None
    plain = tmp_path / "plain.toml"
    plain.write_text("[limits]\nmax_freq_hz = 15.0\n")
    with pytest.raises(BadValueError, match="no fitted \\[model\\]"):
        compare(csv, model=plain)


def test_explain_refuses_a_frame_without_the_columns():
    with pytest.raises(Exception, match="omega_n_rad_s|tau_rot_nm|i_in_a"):
        explain(pd.DataFrame({"x": [1.0, 2.0]}))


def test_quick_sweep_on_a_served_rig_names_the_hidden_effect(served_with_effect):
    seen = []
    with Rig.open(served_with_effect.port) as rig:
        df = rig.torque_sweep(quick=True, progress=lambda done, total, line: seen.append((done, total, line)))
    assert df.attrs["planned"] == 30 and df.attrs["written"] == 30
    # A call after every point: points done of all, and the line with its estimate.
    assert [d for d, _, _ in seen] == list(range(1, 31)), seen
    assert all(t == 30 for _, t, _ in seen)
    assert "elapsed" in seen[0][2] and "left" in seen[0][2] and seen[-1][2].endswith("done")
    assert list(df.columns)[:3] == ["point", "repeat", "t_s"]
    assert {"omega_n_rad_s", "tau_rot_nm", "i_in_a", "backdriven"} <= set(df.columns)
    assert df["i_in_a"].notna().all()
    assert df.attrs["provenance"].startswith("# rig experiment torque-sweep")
    r = explain(df, replicates=20)
    names = [e["name"] for e in r.effects]
    assert "speed-dependent-axial-friction" in names, (r.verdict, names)


def test_hold_release_reproduces_fig5(rig):
    df = rig.hold_release(hold_s=2.0, freq_hz=5.0, release_s=2.0, after_s=1.0)
    assert list(df.columns) == ["t_s", "phase", "state", "output_angle_rad", "cam_speed_rad_s", "current_a"]
    assert set(df["phase"]) == {"hold", "release", "after"}
    fig5 = df.attrs["fig5"]
    # Fig. 5: held without vibration, falls once released, keeps moving after the cam
    # stops (mu_d Lambda = 0.858 < 1).
    assert fig5["held_without_vibration"] is True
    assert fig5["release_to_motion_s"] is not None
    assert fig5["load_drop_m"] > 0.0


def test_procedure_inputs_are_checked(rig):
    with pytest.raises(BadValueError, match="freq_hz 30"):
        rig.hold_release(freq_hz=30)
    with pytest.raises(BadValueError, match="load_nm 9"):
        rig.hold_release(load_nm=9.0)
    with pytest.raises(BadValueError, match="quick=True"):
        rig.torque_sweep(plan="paper", quick=True)
    with pytest.raises(BadValueError, match="cannot read"):
        rig.torque_sweep(plan="/no/such/plan.toml")
    with rig.release(freq_hz=10, seconds=30):
        with pytest.raises(BadValueError, match="release is live"):
            rig.torque_sweep(quick=True)


def test_discover_names_the_hidden_effect_and_keeps_an_existing_csv(tmp_path):
    # `rig discover`'s own loop on the in-process virtual rig with a hidden effect: the
    # effect is named first, the CLI's JSON keys, every round's rows in the CSV.
    csv = tmp_path / "loop.csv"
    with Rig.virtual(preset="ideal", effects=["speed-dependent-axial-friction"], speed=10) as rig:
        r = discover(rig, csv, replicates=20, max_points=60)
        assert {"verdict", "effects", "points_used", "max_points", "settled", "csv", "rounds"} <= set(r)
        assert r.effects and r.effects[0]["name"] == "speed-dependent-axial-friction", (r.verdict, r.effects)
        assert 30 <= r.points_used <= 60 and r.rounds[0]["plan"] == "initial"
        rows = [l for l in csv.read_text().splitlines() if l and not l.startswith("#") and not l.startswith("point")]
        assert len(rows) == r.points_used
        # An existing CSV is refused before the rig moves, and left as it was.
        before = csv.read_bytes()
        with pytest.raises(RigError, match="loop.csv"):
            rig.discover(csv, replicates=20)
        assert csv.read_bytes() == before
        with pytest.raises(BadValueError, match="max_points 5"):
            rig.discover(tmp_path / "other.csv", max_points=5)
