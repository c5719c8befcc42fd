"""Time and state checks of the FMUs: recoverable fmi2Error with a message, the FMU goes on."""
from __future__ import annotations

import json
import math

import pytest
from fmpy import extract, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import fmi2Error
from fmpy.simulation import instantiate_fmu


@pytest.fixture()
def ball(fmu_dir, tmp_path):
    unzipdir = extract(str(fmu_dir["AbuBall"]), unzipdir=str(tmp_path / "ball"))
    md = read_model_description(unzipdir)
    messages = []
    fmu = instantiate_fmu(unzipdir, md, logger=lambda _e, _n, s, _c, m: messages.append((s, m.decode())))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.setReal([vr["torque"]], [1e-3])
    fmu.exitInitializationMode()
    yield fmu, vr, messages
    fmu.terminate()
    fmu.freeInstance()


def error_of(call) -> int:
    with pytest.raises(FMICallException) as info:
        call()
    return info.value.status


def test_do_step_with_a_non_finite_or_mismatched_time_is_an_error_and_recoverable(ball):
    fmu, vr, messages = ball
    fmu.doStep(0.0, 0.1)
    for t, h in ((math.nan, 0.1), (math.inf, 0.1), (0.1, math.nan), (0.1, -0.01), (0.0, 0.1),
                 (0.2, 0.1)):
        assert error_of(lambda: fmu.doStep(t, h)) == fmi2Error, (t, h)
        assert messages[-1][0] == fmi2Error and "fmi2DoStep" in messages[-1][1]
    assert fmu.getReal([vr["omega"]])[0] == pytest.approx(-2 * math.pi * 17 + 1e-3 / 4.5e-5 * 0.1,
                                                          rel=1e-12)  # nothing moved
    fmu.doStep(0.1 + 1e-12, 0.1)  # within the relative tolerance 1e-9: accepted
    assert fmu.getReal([vr["omega"]])[0] == pytest.approx(-2 * math.pi * 17 + 1e-3 / 4.5e-5 * 0.2,
                                                          rel=1e-9)


def test_a_deserialized_state_is_validated_before_use(ball):
    fmu, vr, messages = ball
    fmu.doStep(0.0, 0.5)
    good = fmu.serializeFMUstate(fmu.getFMUstate())
    doc = json.loads(good)
    assert doc["format"] == "abufmu-state-1" and doc["model"] == "AbuBall"

    def tampered(path, value):
        d = json.loads(good)
        target = d
        for key in path[:-1]:
            target = target[key]
        target[path[-1]] = value
        return json.dumps(d).encode()

    bad = {
        "mode 7": tampered(("slave", "plant", 6), 7),
        "NaN omega": tampered(("slave", "plant", 2), math.nan),
        "negative mass": tampered(("slave", "m"), -1.0),
        "missing input": tampered(("slave",), {k: v for k, v in doc["slave"].items() if k != "torque"}),
        "unknown phase": tampered(("phase",), "running"),
        "infinite time": tampered(("time",), math.inf),
        "another model": tampered(("model",), "Staircase"),
        "truncated": good[: len(good) // 2],
    }
    for what, blob in bad.items():
        assert error_of(lambda: fmu.deSerializeFMUstate(blob)) == fmi2Error, what
        assert "fmi2DeSerializeFMUstate" in messages[-1][1], what
    fmu.doStep(0.5, 0.1)
    restored = fmu.deSerializeFMUstate(good)
    fmu.setFMUstate(restored)
    fmu.doStep(0.5, 0.1)  # the restored state is at t = 0.5 s again
    assert fmu.getReal([vr["omega"]])[0] == pytest.approx(-2 * math.pi * 17 + 1e-3 / 4.5e-5 * 0.6,
                                                          rel=1e-12)
