"""Why a flight fails its check, written once (:func:`quadctl.stages.flight_failures`): ``simulate`` says every
reason, ``run`` and the report stop on the first."""

from __future__ import annotations

from types import SimpleNamespace as NS

import pytest

from quadctl import stages
from quadctl.present.mission import mission_text

AT_LIMIT = {"fraction": {"T": 0.9, "L": 0.0, "M": 0.0, "N": 0.0}, "mode": "box"}
MISSED = {"verdict": "saturated", "tolerance": 0.1, "mission_end": 4.0, "duration": 5.0,
          "waypoints": [{"position": [1.0, 0.0, -1.0]}], "missed": [0]}


def _flight(status="ok", message="ok: completed 10 steps", saturation=None, reference=None, allow=()):
    flown = NS(sim=NS(status=status, message=message), flight={"saturation": saturation, "reference": reference})
    return NS(simulation=flown, setup=NS(law="lqr"), cfg=NS(allow=allow))


def test_a_flight_that_passes_has_no_reason():
    assert stages.flight_failures(_flight(), False) == ()
    assert stages.verdict("simulate", _flight()) is None


def test_a_run_that_stopped_is_said_with_its_missed_mission():
    ws = _flight("diverged", "diverged at t = 1 s", saturation=AT_LIMIT, reference=MISSED)
    assert stages.flight_failures(ws, False) == ("diverged at t = 1 s", mission_text(MISSED))
    assert stages.verdict("simulate", ws) == "diverged at t = 1 s"


def test_a_flight_at_its_limits_is_said_with_its_missed_mission_unless_accepted():
    ws = _flight(saturation=AT_LIMIT, reference=MISSED)
    first, mission = stages.flight_failures(ws, False)
    assert first.startswith("the design saturates: T is at a limit 90 % of the run")
    assert mission == mission_text(MISSED) and "waypoints[0]" in mission
    assert stages.verdict("simulate", ws) == first
    for accepted in (stages.flight_failures(ws, True),
                     stages.flight_failures(_flight(saturation=AT_LIMIT, reference=MISSED, allow=("saturation",)),
                                            False)):
        assert accepted == (mission,)
    assert stages.saturation_failure(_flight(saturation=AT_LIMIT), True) is None


@pytest.mark.parametrize("fraction", [0.0, 0.5])
def test_a_flight_within_its_limits_does_not_fail_on_them(fraction):
    sat = {"fraction": {"T": fraction}, "mode": "box"}
    assert stages.saturation_failure(_flight(saturation=sat), False) is None
