"""`python -m scenarios` with the FMI 3.0 FMUs (issue 36): `fmu-path NAME --fmi 3` names
build/fmu3's, and `run CYCLE --fmi 3` steps the FMI 3.0 drive (scenarios/cosim/standard.py) with
the results of the FMI 2.0 one, bit for bit: the same model code is behind both standards, so
summary.json (but for the wall-clock figures) and trace.csv are the same bytes. A minute of UDDS
in the default run; the whole UDDS behind the `slow` marker."""
from __future__ import annotations

import json

import pytest

from scenarios.__main__ import main
from scenarios.vehicle.cycles import load_cycle, segment

from conftest import BUILD_FMU3, fmu3_path

#: summary.json's figures that measure the machine, not the run
WALL_CLOCK = ("wall_s", "real_time_factor")
#: s, a busy minute of UDDS (accelerations, cruising, regenerative braking), as test_scenarios.py's
UDDS_MINUTE = (180, 260)


def test_fmu_path_takes_the_fmi_version(tmp_path, capsys):
    """No FMU is read: the files only need to be there."""
    build = tmp_path / "build"
    for folder in ("fmu", "fmu3"):
        (build / folder).mkdir(parents=True)
        (build / folder / "IpmsmDrive.fmu").write_bytes(b"")
    assert main(["--build", str(build), "fmu-path", "IpmsmDrive"]) == 0
    assert capsys.readouterr().out.strip() == str(build / "fmu" / "IpmsmDrive.fmu")
    assert main(["--build", str(build), "fmu-path", "IpmsmDrive", "--fmi", "3"]) == 0
    assert capsys.readouterr().out.strip() == str(build / "fmu3" / "IpmsmDrive.fmu")
    assert main(["--build", str(build), "fmu-path", "IpmsmPlant", "--fmi", "3"]) == 2
    assert str(build / "fmu3" / "IpmsmPlant.fmu") in capsys.readouterr().err
    assert main(["--build", str(build), "fmu-path", "IpmsmControllerPlant", "--fmi", "3"]) == 2
    assert "FMI 2.0" in capsys.readouterr().err
    with pytest.raises(SystemExit) as e:
        main(["--build", str(build), "fmu-path", "IpmsmDrive", "--fmi", "1"])
    assert e.value.code == 2


def test_fmu_path_names_this_builds_fmi3_drive(capsys):
    path = fmu3_path("IpmsmDrive")
    assert main(["--build", str(BUILD_FMU3.parent), "fmu-path", "IpmsmDrive", "--fmi", "3"]) == 0
    assert capsys.readouterr().out.strip() == str(path)


def _run(cycle: str, fmi: int, out, *options: str) -> tuple[dict, bytes]:
    assert main(["--build", str(BUILD_FMU3.parent), "run", cycle, "--fmi", str(fmi), "--out", str(out),
                 *options]) == 0
    summary = json.loads((out / "summary.json").read_text())
    return {k: v for k, v in summary.items() if k not in WALL_CLOCK}, (out / "trace.csv").read_bytes()


def _same_runs(cycle: str, tmp_path, *options: str) -> dict:
    for name in ("IpmsmController", "IpmsmPlant", "IpmsmDrive"):
        fmu3_path(name)
    s2, trace2 = _run(cycle, 2, tmp_path / "fmi2", *options)
    s3, trace3 = _run(cycle, 3, tmp_path / "fmi3", *options)
    differ = {k: (s2[k], s3.get(k)) for k in s2 if s2[k] != s3.get(k)}
    assert not differ and s2.keys() == s3.keys(), differ
    assert trace3 == trace2, "trace.csv of the FMI 3.0 run differs from the FMI 2.0 run's"
    print(f"\n[{cycle} --fmi 3 {' '.join(options)}] {s3['distance_km']:.3f} km, {s3['Wh_per_km']:.3f} Wh/km, "
          f"{s3['steps']} steps: summary.json and trace.csv ({len(trace3)} bytes) as --fmi 2's")
    return s3


def test_run_fmi3_is_the_fmi2_run_bit_for_bit(tmp_path):
    minute = segment(load_cycle("UDDS"), *UDDS_MINUTE)
    csv = tmp_path / "udds_minute.csv"
    csv.write_text("time_s,speed_mps\n" + "".join(f"{float(t)!r},{float(v)!r}\n" for t, v in zip(*minute)))
    s = _same_runs(str(csv), tmp_path)
    assert s["distance_km"] > 0.5 and s["energy_battery_Wh"] > 0.0  # the car really drove


def test_the_reference_loop_on_fmi3_is_the_fmi2_loop_bit_for_bit(tmp_path):
    """The controller and the plant coupled in Python (--backend reference), each through the
    FMI 3.0 adapter: a few seconds of driving off (its loop steps every 100 us in Python)."""
    csv = tmp_path / "start.csv"
    csv.write_text("time_s,speed_mps\n0,0\n2,3\n4,5\n5,4\n")
    s = _same_runs(str(csv), tmp_path, "--backend", "reference")
    assert s["backend"] == "reference" and s["distance_km"] > 0.01


@pytest.mark.slow
def test_run_udds_fmi3_is_the_fmi2_run_bit_for_bit(tmp_path):
    _same_runs("UDDS", tmp_path)
