"""quadctl export --to crazyflie: the app's adapter flies what the simulation flew, in the firmware's frames.

The firmware is not here: the firmware types the adapter uses are declared below, by this test,
from the firmware's documented out-of-tree controller interface (``controller.h``,
``stabilizer_types.h``, ``power_distribution.h`` of bitcraze/crazyflie-firmware; names, fields and
units, no code). A host-compiled harness feeds the adapter the firmware's view of a simulated
flight (the state of ``sim.npz`` in the firmware's frames and units, built here independently
with scipy's rotations) one 1 kHz stabilizer call at a time, and the motor forces it writes must be
the simulation's rotor thrusts. Each frame conversion is checked alone on a hand-made state.
"""

from __future__ import annotations

import copy
import os
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
import yaml
from scipy.spatial.transform import Rotation
from typer.testing import CliRunner

from quadctl import artifacts, config
from quadctl.cli.app import app
from quadctl.errors import ConfigError
from quadctl.export import crazyflie, crazyflie_platform
from quadctl.layout import STATE_INDEX

FIRMWARE_HEADERS = {
    # from stabilizer_types.h (and imu_types.h's Axis3f): only the types the adapter reads or writes
    "stabilizer_types.h": """
#ifndef TEST_STABILIZER_TYPES_H
#define TEST_STABILIZER_TYPES_H
#include <stdint.h>
#include <stdbool.h>
typedef union { struct { float x; float y; float z; }; float axis[3]; } Axis3f;
typedef uint32_t stabilizerStep_t;
typedef struct attitude_s { uint32_t timestamp; float roll; float pitch; float yaw; } attitude_t;
struct vec3_s { uint32_t timestamp; float x; float y; float z; };
typedef struct vec3_s point_t;
typedef struct vec3_s velocity_t;
typedef struct vec3_s acc_t;
typedef struct vec3_s jerk_t;
typedef struct quaternion_s {
  union { struct { float q0; float q1; float q2; float q3; }; struct { float x; float y; float z; float w; }; };
} quaternion_t;
typedef struct baro_s { float pressure; float temperature; float asl; } baro_t;
typedef struct sensorData_s { Axis3f acc; Axis3f gyro; Axis3f mag; baro_t baro; uint64_t interruptTimestamp; }
  sensorData_t;
typedef struct state_s {
  attitude_t attitude; quaternion_t attitudeQuaternion; point_t position; velocity_t velocity; acc_t acc;
} state_t;
#define STABILIZER_NR_OF_MOTORS 4
typedef enum control_mode_e { controlModeLegacy = 0, controlModeForceTorque = 1, controlModeForce = 2 }
  control_mode_t;
typedef struct control_s {
  union {
    struct { int16_t roll; int16_t pitch; int16_t yaw; float thrust; };
    struct { float thrustSi; union { float torque[3]; struct { float torqueX; float torqueY; float torqueZ; }; }; };
    float normalizedForces[STABILIZER_NR_OF_MOTORS];
  };
  control_mode_t controlMode;
} control_t;
typedef enum mode_e { modeDisable = 0, modeAbs, modeVelocity } stab_mode_t;
typedef struct { stab_mode_t x, y, z, roll, pitch, yaw, quat; } setpoint_mode_t;
typedef struct setpoint_s {
  uint32_t timestamp; attitude_t attitude; attitude_t attitudeRate; quaternion_t attitudeQuaternion; float thrust;
  point_t position; velocity_t velocity; acc_t acceleration; jerk_t jerk; bool velocity_body; setpoint_mode_t mode;
} setpoint_t;
#endif
""",
    # from controller.h: the three functions an out-of-tree controller implements
    "controller.h": """
#include "stabilizer_types.h"
void controllerOutOfTreeInit(void);
bool controllerOutOfTreeTest(void);
void controllerOutOfTree(control_t *control, const setpoint_t *setpoint, const sensorData_t *sensors,
                         const state_t *state, const stabilizerStep_t stabilizerStep);
""",
    # from power_distribution.h: the platform's total maximum thrust (4 THRUST_MAX)
    "power_distribution.h": "float powerDistributionGetMaxThrust(void);\n",
}
THRUST_MAX = 0.12
"""The harness's maximum rotor thrust (the firmware's THRUST_MAX of the CF 2.1+)."""

HARNESS = r"""
#include <stdio.h>
#include <string.h>
#include "controller.h"
#include "quadctl_crazyflie.h"

float powerDistributionGetMaxThrust(void) { return 4.0f * TEST_THRUST_MAX; }

/* one record: modes x, y, z, yaw, velocity_body; setpoint position (3), velocity (3), yaw, yaw rate;
   state position (3), velocity (3), quaternion w x y z, attitude roll pitch yaw; gyro (3) */
#define NREC 29
#define REFERENCE_DT 0.01f
int main(int argc, char **argv) {
  float r[NREC];
  uint32_t tick = 0;
  int state_only = argc > 1 && strcmp(argv[1], "state") == 0;
  int reference_only = argc > 1 && strcmp(argv[1], "reference") == 0;
  static quadctl_reference ref;  /* reference mode: held from record to record, as the app holds its own */
  controllerOutOfTreeInit();
  if (!controllerOutOfTreeTest()) return 1;
  while (fread(r, sizeof(float), NREC, stdin) == NREC) {
    setpoint_t sp; state_t st; sensorData_t se; control_t ctl;
    memset(&sp, 0, sizeof sp); memset(&st, 0, sizeof st); memset(&se, 0, sizeof se); memset(&ctl, 0, sizeof ctl);
    sp.mode.x = (stab_mode_t)r[0]; sp.mode.y = (stab_mode_t)r[1]; sp.mode.z = (stab_mode_t)r[2];
    sp.mode.yaw = (stab_mode_t)r[3]; sp.velocity_body = r[4] != 0.0f;
    sp.position.x = r[5]; sp.position.y = r[6]; sp.position.z = r[7];
    sp.velocity.x = r[8]; sp.velocity.y = r[9]; sp.velocity.z = r[10];
    sp.attitude.yaw = r[11]; sp.attitudeRate.yaw = r[12];
    st.position.x = r[13]; st.position.y = r[14]; st.position.z = r[15];
    st.velocity.x = r[16]; st.velocity.y = r[17]; st.velocity.z = r[18];
    st.attitudeQuaternion.w = r[19]; st.attitudeQuaternion.x = r[20];
    st.attitudeQuaternion.y = r[21]; st.attitudeQuaternion.z = r[22];
    st.attitude.roll = r[23]; st.attitude.pitch = r[24]; st.attitude.yaw = r[25];
    se.gyro.x = r[26]; se.gyro.y = r[27]; se.gyro.z = r[28];
    if (state_only) {
      quadctl_real x[QUADCTL_NX];
      int i;
      quadctl_cf_state(&st, &se, x);
      for (i = 0; i < QUADCTL_NX; ++i) printf("%.9g ", (double)x[i]);
      printf("\n");
      continue;
    }
    if (reference_only) {  /* quadctl's x_ref after this setpoint, REFERENCE_DT after the last */
      int i;
      quadctl_cf_reference(&ref, &sp, REFERENCE_DT);
      for (i = 0; i < QUADCTL_NX; ++i) printf("%.9g ", (double)ref.x[i]);
      printf("\n");
      continue;
    }
    controllerOutOfTree(&ctl, &sp, &se, &st, tick++);
    if (ctl.controlMode == controlModeForce)
      printf("%d %.9g %.9g %.9g %.9g\n", (int)ctl.controlMode, (double)ctl.normalizedForces[0],
             (double)ctl.normalizedForces[1], (double)ctl.normalizedForces[2], (double)ctl.normalizedForces[3]);
    else
      printf("%d %.9g %.9g %.9g %.9g\n", (int)ctl.controlMode, (double)ctl.thrustSi, (double)ctl.torqueX,
             (double)ctl.torqueY, (double)ctl.torqueZ);
  }
  return 0;
}
"""
MODE_DISABLE, MODE_ABS, MODE_VELOCITY = 0, 1, 2
FLU = np.diag([1.0, -1.0, -1.0])
"""x forward (north), y left, z up from NED / FRD, and back."""


def compiler() -> str:
    for name in ("cc", "gcc", "clang"):
        path = shutil.which(name)
        if path:
            return path
    pytest.skip("no host C compiler (cc, gcc, clang): the harness cannot be built here")


def build_harness(app: Path, where: Path) -> Path:
    """The adapter, the exported controller and the harness, compiled for this machine in float."""
    inc = where / "firmware"
    inc.mkdir(exist_ok=True)
    for name, text in FIRMWARE_HEADERS.items():
        (inc / name).write_text(text)
    (where / "harness.c").write_text(HARNESS)
    exe = where / "harness"
    cmd = [compiler(), "-std=c11", "-O1", "-Wall", "-Wextra", "-Werror", "-Wdouble-promotion", "-DQUADCTL_FLOAT",
           f"-DTEST_THRUST_MAX={THRUST_MAX!r}f", f"-I{inc}", f"-I{app / 'src'}", str(where / "harness.c"),
           str(app / "src" / "quadctl_crazyflie.c"), str(app / "src" / "quadctl_controller.c"), "-lm", "-o", str(exe)]
    out = subprocess.run(cmd, capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    return exe


def export_app(cfg_path: Path, out: Path, *args: str) -> None:
    res = CliRunner().invoke(app, ["export", "--to", "crazyflie", "-c", str(cfg_path), "-o", str(out), *args])
    assert res.exit_code == 0, res.output


def firmware_view(x: np.ndarray) -> np.ndarray:
    """(N, 17) the firmware's state of quadctl states ``x`` (N, 12): position, world velocity
    (FLU), quaternion (w, x, y, z; body FLU to world FLU), attitude in degrees (legacy pitch),
    gyro in deg/s (FLU); built with scipy's rotations, not the adapter's formulas."""
    x = np.atleast_2d(x)
    R_ned = Rotation.from_euler("ZYX", x[:, [8, 7, 6]]).as_matrix()  # body FRD -> NED
    R_flu = FLU @ R_ned @ FLU
    q = Rotation.from_matrix(R_flu).as_quat()  # x, y, z, w
    v_ned = np.einsum("nij,nj->ni", R_ned, x[:, 3:6])
    deg = np.degrees
    return np.column_stack([
        x[:, 0], -x[:, 1], -x[:, 2], v_ned @ FLU, q[:, 3], q[:, :3],
        deg(x[:, 6]), deg(x[:, 7]), -deg(x[:, 8]), deg(x[:, 9]), -deg(x[:, 10]), -deg(x[:, 11])])


def records(view: np.ndarray, setpoints: np.ndarray) -> bytes:
    """The harness's input: one row of 29 floats a stabilizer call."""
    return np.column_stack([setpoints, view]).astype(np.float32).tobytes()


def run_harness(exe: Path, data: bytes, *args: str) -> np.ndarray:
    out = subprocess.run([str(exe), *args], input=data, capture_output=True)
    assert out.returncode == 0, out.stderr.decode()
    return np.loadtxt(out.stdout.decode().splitlines(), ndmin=2)


def crazyflie_config(tmp: Path, **changes) -> Path:
    data = copy.deepcopy(config.load("crazyflie").model_dump(mode="json", exclude_none=True))
    for key, value in changes.items():
        data[key] = value
    path = tmp / "config.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def simulated(cfg_path: Path, out: Path):
    res = CliRunner().invoke(app, ["simulate", "-c", str(cfg_path), "-o", str(out)])
    assert res.exit_code == 0, res.output
    return np.load(out / "sim.npz")


MISSION = dict(
    subsystems={"altitude": {"states": ["pD", "w"], "inputs": ["T"]},
                "roll": {"states": ["pE", "v", "phi", "p"], "inputs": ["A"]},
                "pitch": {"states": ["pN", "u", "theta", "q"], "inputs": ["E"]},
                "yaw": {"states": ["psi", "r"], "inputs": ["R"]}},
    lqr={"altitude": {"Q": [4, 4], "R": [100]},
         "roll": {"Q": [25, 1, 100, 0.25], "R": [444444]},
         "pitch": {"Q": [25, 1, 100, 0.25], "R": [444444]},
         "yaw": {"Q": [25, 0.25], "R": [1.0e8]}},
)
"""The crazyflie config with the position regulated (in the roll and pitch subsystems)."""


def mission_simulation():
    return {"duration": 6.0, "dt": "auto",
            "reference": {"trajectory": "step", "tolerance": 0.1,
                          "waypoints": [{"position": [0.3, 0.0, -1.0], "hold": 1.5},
                                        {"position": [0.3, 0.3, -1.2], "yaw": 0.5, "hold": 1.5},
                                        {"position": [0.0, 0.0, -1.0], "yaw": 0.0}]}}


def hover_setpoints(n: int) -> np.ndarray:
    """The velocity setpoint (vx = vy = 0), z = 1 m and yaw 0, ``n`` calls."""
    setpoints = np.zeros((n, 13))
    setpoints[:, 0:4] = [MODE_VELOCITY, MODE_VELOCITY, MODE_ABS, MODE_ABS]
    setpoints[:, 7] = 1.0  # z = 1 m up
    return setpoints


@pytest.fixture(scope="module")
def hover(tmp_path_factory):
    """crazyflie's hover hold from its initial offset, simulated, and its app in both output modes, built."""
    tmp = tmp_path_factory.mktemp("cf-hover")
    cfg = crazyflie_config(tmp)
    sim = simulated(cfg, tmp / "run")
    from quadctl.export import prepare
    from quadctl.setup import setup_of

    act = prepare(setup_of(config.load(cfg))).loop.actuators
    exes = {}
    for mode in ("force", "force-torque"):
        export_app(cfg, tmp / mode, "--setpoint", "velocity", "--mode", mode)
        (tmp / f"build-{mode}").mkdir()
        exes[mode] = build_harness(tmp / mode, tmp / f"build-{mode}")
    return sim, act, exes


@pytest.mark.parametrize("mode", ["force", "force-torque"])
def test_the_adapter_writes_the_simulated_hover_holds_motor_forces(hover, mode):
    """crazyflie, hover hold from its initial offset, the firmware's state of each simulated millisecond:
    force mode writes the simulation's rotor thrusts (over the firmware's maximum), force-torque mode its
    thrust and torques in the firmware's body axes (x forward, y left, z up)."""
    sim, act, exes = hover
    x, n = sim["x"], len(sim["t"])
    got = run_harness(exes[mode], records(firmware_view(x), hover_setpoints(n)))
    if mode == "force":
        assert np.all(got[:, 0] == 2)  # controlModeForce
        want, got_si = act.commands(sim["u"]), got[:, 1:] * THRUST_MAX
        assert np.ptp(want[:, 0]) > 1e-3  # the run moves the rotors: the comparison is not of constants
    else:
        assert np.all(got[:, 0] == 1)  # controlModeForceTorque
        want, got_si = sim["u"] * [1.0, 1.0, -1.0, -1.0], got[:, 1:]
    err = np.max(np.abs(got_si - want))
    assert err < 1e-6, f"max |output - simulated| = {err:.3e} (N, N m)"


def test_a_stop_zeroes_the_motors_and_the_next_start_is_afresh(hover):
    """51 ms of flight (an odd count: mid-sample), 10 ms without an altitude setpoint (the commander
    stopped: forces 0), then the run again from its start: the controller restarted (its sampling
    phase, clock, held yaw and position), so the forces are the simulation's from its first sample."""
    sim, act, exes = hover
    x, n = sim["x"], 400
    view, sp = firmware_view(x[:n]), hover_setpoints(n)
    stopped = hover_setpoints(10)
    stopped[:, 2] = 0  # mode.z = modeDisable
    data = records(view[:51], sp[:51]) + records(view[:10], stopped) + records(view, sp)
    got = run_harness(exes["force"], data)
    assert np.all(got[51:61, 1:] == 0.0)
    err = np.max(np.abs(got[61:, 1:] * THRUST_MAX - act.commands(sim["u"][:n])))
    assert err < 1e-6, f"after the restart: max |force - simulated| = {err:.3e} N"


def test_the_adapter_flies_the_simulated_waypoint_mission(tmp_path):
    """A waypoint mission (steps) with the position regulated: the commander's position setpoint (x,
    y, z, yaw from the simulation's reference) gives the simulation's forces."""
    cfg = crazyflie_config(tmp_path, **MISSION, simulation=mission_simulation())
    sim = simulated(cfg, tmp_path / "run")
    export_app(cfg, tmp_path / "app")  # --setpoint position
    exe = build_harness(tmp_path / "app", tmp_path)
    x, xr, n = sim["x"], sim["x_ref"], len(sim["t"])
    setpoints = np.zeros((n, 13))
    setpoints[:, 0:4] = MODE_ABS
    setpoints[:, 5:8] = np.column_stack([xr[:, 0], -xr[:, 1], -xr[:, 2]])
    setpoints[:, 11] = -np.degrees(xr[:, 8])
    got = run_harness(exe, records(firmware_view(x), setpoints))
    from quadctl.export import prepare
    from quadctl.setup import setup_of

    act = prepare(setup_of(config.load(cfg))).loop.actuators
    want = act.commands(sim["u"])
    err = np.max(np.abs(got[:, 1:] * THRUST_MAX - want))
    assert err < 1e-6, f"max |force - simulated rotor thrust| = {err:.3e} N"
    assert np.ptp(xr[:, 1]) > 0.2 and np.ptp(xr[:, 8]) > 0.4  # the mission moves east and turns


@pytest.fixture(scope="module")
def state_harness(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("cf-state")
    cfg = crazyflie_config(tmp)
    export_app(cfg, tmp / "app", "--setpoint", "velocity")
    return build_harness(tmp / "app", tmp)


def _state(exe, **fw) -> dict:
    """quadctl's x from one hand-made firmware state (keyword: field = value)."""
    row = np.zeros(29)
    row[19] = 1.0  # the identity quaternion
    fields = {"px": 13, "py": 14, "pz": 15, "vx": 16, "vy": 17, "vz": 18, "qw": 19, "qx": 20, "qy": 21, "qz": 22,
              "roll": 23, "pitch": 24, "yaw": 25, "gx": 26, "gy": 27, "gz": 28}
    for k, v in fw.items():
        row[fields[k]] = v
    x = run_harness(exe, row.astype(np.float32).tobytes(), "state")[0]
    return {name: x[i] for name, i in STATE_INDEX.items()}


S = np.sin(np.radians(10.0) / 2), np.cos(np.radians(10.0) / 2)


@pytest.mark.parametrize("case, fw, want", [
    # nose up 10 deg: the firmware's legacy pitch +10, its quaternion a rotation about y (left) by -10 deg
    # (FLU pitch down-positive); flying forward level in the world is body u cos, w sin (FRD: w down
    # positive: moving forward with the nose up moves the body down its z)
    ("nose up", dict(pitch=10.0, qw=S[1], qy=-S[0], vx=1.0, gy=-20.0),
     dict(theta=np.radians(10.0), u=np.cos(np.radians(10.0)), w=np.sin(np.radians(10.0)), q=np.radians(20.0))),
    # rolled right 10 deg: roll +10 (about x forward), moving right (world y -1): body v = cos 10
    ("rolled right", dict(roll=10.0, qw=S[1], qx=S[0], vy=-1.0, gx=30.0),
     dict(phi=np.radians(10.0), v=np.cos(np.radians(10.0)), w=-np.sin(np.radians(10.0)), p=np.radians(30.0))),
    # yawed left 10 deg: firmware yaw +10 (counter-clockwise from above), psi -10 deg; turning left (gz +)
    ("yawed left", dict(yaw=10.0, qw=S[1], qz=S[0], vx=1.0, gz=15.0),
     dict(psi=-np.radians(10.0), u=np.cos(np.radians(10.0)), v=np.sin(np.radians(10.0)), r=-np.radians(15.0))),
    # level, moving north-east-up at (1, 2, 3) m/s from (4, 5, 6) m: x north, y left = west, z up
    ("north-east-up", dict(px=4.0, py=5.0, pz=6.0, vx=1.0, vy=-2.0, vz=3.0),
     dict(pN=4.0, pE=-5.0, pD=-6.0, u=1.0, v=2.0, w=-3.0)),
    # yaw past the wrap: firmware yaw -190 deg is psi 190 deg, wrapped to -170 deg
    ("yaw wrapped", dict(yaw=-190.0), dict(psi=np.radians(-170.0))),
])
def test_each_frame_conversion_on_a_hand_made_state(state_harness, case, fw, want):
    got = _state(state_harness, **fw)
    for name, value in want.items():
        assert got[name] == pytest.approx(value, abs=2e-6), f"{case}: {name}"
    for name in set(STATE_INDEX) - set(want):
        assert abs(got[name]) < 2e-6, f"{case}: {name} should be 0"


def test_a_yaw_rate_and_velocity_setpoint_turns_the_reference_as_the_frames_say(state_harness):
    """The commander's yaw rate +30 deg/s (counter-clockwise seen from above, z up: turning left) is
    ``r = -30 deg/s`` in FRD, and the reference's heading integrates it, ``psi_k = -30 deg/s k dt``; its
    world velocity (1, 0.5) m/s (x north, y west) is ``(vN, vE) = (1, -0.5)``, its position integrates
    that, and the body velocity of the turning reference is that velocity seen at ``psi_k``."""
    n, dt, rate = 10, 0.01, 30.0  # records, s (the harness's REFERENCE_DT), deg/s
    rows = np.zeros((n, 29))
    rows[:, 19] = 1.0  # identity quaternion (the state is not read)
    rows[:, 0:4] = [MODE_VELOCITY, MODE_VELOCITY, MODE_ABS, MODE_VELOCITY]
    rows[:, 7], rows[:, 8], rows[:, 9], rows[:, 12] = 1.0, 1.0, 0.5, rate
    x = run_harness(state_harness, rows.astype(np.float32).tobytes(), "reference")
    k = np.arange(1, n + 1)
    psi = -np.radians(rate) * k * dt
    tol = 1e-6  # single precision of the firmware's floats, on values of order one
    np.testing.assert_allclose(x[:, STATE_INDEX["r"]], -np.radians(rate), atol=tol)
    np.testing.assert_allclose(x[:, STATE_INDEX["psi"]], psi, atol=tol)
    np.testing.assert_allclose(x[:, STATE_INDEX["pN"]], k * dt * 1.0, atol=tol)
    np.testing.assert_allclose(x[:, STATE_INDEX["pE"]], -k * dt * 0.5, atol=tol)
    np.testing.assert_allclose(x[:, STATE_INDEX["pD"]], -1.0, atol=tol)
    vn, ve = 1.0, -0.5
    np.testing.assert_allclose(x[:, STATE_INDEX["u"]], np.cos(psi) * vn + np.sin(psi) * ve, atol=tol)
    np.testing.assert_allclose(x[:, STATE_INDEX["v"]], -np.sin(psi) * vn + np.cos(psi) * ve, atol=tol)


def test_an_axis_the_setpoint_leaves_out_holds_still_where_it_was(state_harness):
    """Setpoints that stop coming while the vehicle flies a velocity: after 0.5 s the firmware's supervisor
    levels it out (its WarningLevelOut: x and y modeDisable, z kept). Every axis the setpoint leaves out holds
    its last position or yaw, still: velocity and yaw rate 0. The app kept the last velocity and yaw rate,
    and flew on at 1 m/s."""
    n, dt, rate = 10, 0.01, 30.0  # records of each kind, s (the harness's REFERENCE_DT), deg/s
    rows = np.zeros((2 * n, 29))
    rows[:, 19] = 1.0  # identity quaternion (the state is not read)
    rows[:, 7] = 1.0  # z = 1 m up
    rows[:n, 0:4] = [MODE_VELOCITY, MODE_VELOCITY, MODE_ABS, MODE_VELOCITY]
    rows[:n, 8], rows[:n, 9], rows[:n, 12] = 1.0, 0.5, rate
    rows[n:, 0:4] = [MODE_DISABLE, MODE_DISABLE, MODE_ABS, MODE_DISABLE]
    x = run_harness(state_harness, rows.astype(np.float32).tobytes(), "reference")
    tol = 1e-6  # single precision of the firmware's floats, on values of order one
    for name in ("u", "v", "w", "r"):
        np.testing.assert_allclose(x[n:, STATE_INDEX[name]], 0.0, atol=tol, err_msg=name)
    for name, last in (("pN", n * dt * 1.0), ("pE", -n * dt * 0.5), ("pD", -1.0), ("psi", -np.radians(rate) * n * dt)):
        np.testing.assert_allclose(x[n - 1:, STATE_INDEX[name]], last, atol=tol, err_msg=name)


@pytest.mark.parametrize("case", ["nose up", "rolled right", "yawed left"])
def test_the_test_firmware_view_agrees_with_the_hand_made_states(case):
    """The harness's state builder (scipy) gives the hand-made quaternions: the two checks check each other."""
    x = np.zeros(12)
    x[{"nose up": 7, "rolled right": 6, "yawed left": 8}[case]] = np.radians(10.0) * (-1 if case == "yawed left" else 1)
    view = firmware_view(x)[0]
    q = {"nose up": (S[1], 0, -S[0], 0), "rolled right": (S[1], S[0], 0, 0), "yawed left": (S[1], 0, 0, S[0])}[case]
    assert view[6:10] == pytest.approx(q, abs=1e-12)


@pytest.mark.parametrize("args, message", [
    (["--set", "controller.rate=300", "--setpoint", "velocity"],
     r"^quadctl: error: controller.rate = 300 Hz does not divide the Crazyflie's 1000 Hz stabilizer loop"),
    (["--setpoint", "position"],
     r"^quadctl: error: subsystems: the partition leaves pN, pE free \(in no regulated subsystem\), so a "
     r"position setpoint cannot be followed: regulate pN, pE \(add them to a subsystem with regulate: true\) or "
     r"export with --setpoint velocity \(the hover setpoint: vx, vy, z, yaw rate\)$"),
    (["--set", "motors.numbering=px4", "--setpoint", "velocity"],
     r"^quadctl: error: motors.numbering: rotors 1-4 are front_right, rear_left, front_left, rear_right spinning "
     r"ccw, ccw, cw, cw, not the Crazyflie's motors M1-M4"),
    (["--set", "motors=null"],  # force mode, the default, writes rotor thrusts: the section to add, named
     r"^quadctl: error: motors: is absent: force mode writes each rotor's thrust, so the config needs its rotors: "
     r"add them, motors: \{layout: x, arm_length: 0.046, max_thrust: 0.12, min_thrust: 0.01282, torque_coefficient: "
     r"0.006993\} \(the firmware's; your vehicle's own where they differ\), or export with --mode force-torque$"),
    (["--set", "controller.filters.gyro.cutoff=30"],  # the firmware's 80 Hz low-pass is the one the app flies
     r"^quadctl: error: controller.filters: second-order low-pass at 30 Hz, but the firmware's sensor driver "
     r"low-passes the gyro itself \(second-order low-pass at 80 Hz, src/hal/src/sensors_bmi088_bmp3xx.c "
     r"GYRO_LPF_CUTOFF_FREQ\) before the app reads it, and the app flies that filter alone: set controller.filters: "
     r"\{gyro: \{cutoff: 80, order: 2\}\}, the filter the vehicle has, or remove controller.filters$"),
])
def test_an_app_the_adapter_cannot_serve_is_refused_with_one_line_and_nothing_written(tmp_path, args, message):
    out = tmp_path / "app"
    res = CliRunner().invoke(app, ["export", "--to", "crazyflie", "-c", "crazyflie", "-o", str(out), *args])
    assert res.exit_code == 2, res.output
    lines = res.output.strip().splitlines()
    assert len(lines) == 1 and re.match(message, lines[0]), res.output
    assert not out.exists()


@pytest.mark.parametrize("to, args, message", [
    ("c", ["--setpoint", "velocity"], r"--setpoint velocity: only --to crazyflie takes it \(the app's commander and "
                                      r"mixer\), not --to c; drop it, or export --to crazyflie$"),
    ("json", ["--mode", "force"], r"--mode force: only --to crazyflie takes it .*, not --to json;"),
    ("mat", ["--setpoint", "position", "--mode", "force-torque"],
     r"--setpoint position and --mode force-torque: only --to crazyflie takes them"),
])
def test_the_app_s_options_with_another_target_are_refused_not_ignored(tmp_path, to, args, message):
    """--setpoint and --mode shape the Crazyflie app alone: with --to c they were dropped without a word, and
    the C controller written was not the one asked for."""
    out = tmp_path / "out"
    res = CliRunner().invoke(app, ["export", "--to", to, "-c", "crazyflie", "-o", str(out), *args])
    assert res.exit_code == 2, res.output
    lines = res.output.strip().splitlines()
    assert len(lines) == 1 and re.search(r"^quadctl: error: " + message, lines[0]), res.output
    assert not out.exists()


def test_the_bundled_crazyflie_config_exports_with_no_setpoint_option(tmp_path):
    """Its partition leaves pN, pE free (guidance: regulate: false), so the app follows the velocity setpoint
    unasked; a config that regulates the position follows the position setpoint."""
    res = CliRunner().invoke(app, ["export", "--to", "crazyflie", "-c", "crazyflie", "-o", str(tmp_path / "app"),
                                   "--json"])
    assert res.exit_code == 0, res.output
    import json

    assert json.loads(res.stdout)["crazyflie"]["setpoint"] == "velocity"
    assert (tmp_path / "app" / "src" / "quadctl_crazyflie.c").is_file()
    from quadctl.export import prepare
    from quadctl.setup import setup_of

    held = prepare(setup_of(config.load(str(crazyflie_config(tmp_path, **MISSION)))))
    assert crazyflie.flyable_setpoints(held) == ("position", "velocity")
    assert crazyflie.default_setpoint(held) == "position"


def test_the_firmwares_gyro_filter_in_the_config_is_left_to_the_firmware_not_run_twice(tmp_path):
    """The adapter reads sensors->gyro, which the firmware's sensor driver has low-passed at 80 Hz for every
    controller. A config that models that filter (controller.filters, so that its margins and simulation have
    it) exported an app whose C filtered the rates a second time: the app now leaves it to the firmware, and its
    header says so; the plain C export still runs it on the raw rates."""
    sets = ["--set", "controller.filters.gyro.cutoff=80", "--set", "controller.filters.gyro.order=2"]
    export_app(Path("crazyflie"), tmp_path / "app", *sets)
    header = (tmp_path / "app" / "src" / "quadctl_controller.h").read_text()
    assert "#define QUADCTL_NG 0 " in header
    assert re.sub(r"\s*\n \*\s*", " ", header).count(
        "The config's gyro filter (controller.filters: second-order low-pass at 80 Hz, the firmware's sensor "
        "driver's (src/hal/src/sensors_bmi088_bmp3xx.c GYRO_LPF_CUTOFF_FREQ)) is the vehicle's") == 1
    res = CliRunner().invoke(app, ["export", "--to", "c", "-c", "crazyflie", "-o", str(tmp_path / "c"), *sets])
    assert res.exit_code == 0, res.output
    assert "#define QUADCTL_NG 6 " in (tmp_path / "c" / "quadctl_controller.h").read_text()


def test_an_app_of_a_design_on_raw_rates_says_the_firmware_filters_them(tmp_path):
    """crazyflie has no controller.filters: its margins and simulation read raw rates the vehicle does not give
    the app, and the export says so, naming the filter to set."""
    res = CliRunner().invoke(app, ["export", "--to", "crazyflie", "-c", "crazyflie", "-o", str(tmp_path / "app")])
    assert res.exit_code == 0, res.output
    assert ("quadctl: note: the firmware low-passes the gyro (second-order low-pass at 80 Hz, "
            "src/hal/src/sensors_bmi088_bmp3xx.c GYRO_LPF_CUTOFF_FREQ) before the app's law reads it, but the config "
            "has no controller.filters") in res.stderr
    assert "set controller.filters: {gyro: {cutoff: 80, order: 2}}" in res.stderr
    res = CliRunner().invoke(app, ["export", "--to", "crazyflie", "-c", "crazyflie", "-o", str(tmp_path / "f"),
                                   "--set", "controller.filters.gyro.cutoff=80"])
    assert res.exit_code == 0 and "low-passes the gyro" not in res.stderr, res.output


def test_an_app_of_a_design_without_rotor_lag_names_the_lag_to_check_it_on(tmp_path):
    """crazyflie gives its rotors no lag; the identified Crazyflie's rotors lag 65 ms, on which its design is
    unstable: the export says so and names the command that checks it, which does fail (exit 1, unstable);
    a config that models a lag gets no such note."""
    from quadctl.export.crazyflie import ROTOR_LAG

    res = CliRunner().invoke(app, ["export", "--to", "crazyflie", "-c", "crazyflie", "-o", str(tmp_path / "app")])
    assert res.exit_code == 0, res.output
    check = f"quadctl margins -c crazyflie --set motors.time_constant={ROTOR_LAG:g}"
    assert ("quadctl: note: the config gives the rotors no lag (motors.time_constant), but a Crazyflie's rotors lag "
            f"about 65 ms (quadctl identify on its flight logs): check the design on it before you fly, {check}, "
            "and design with it (controller.rotor_lag: include) if it does not hold") in res.stderr
    margins = CliRunner().invoke(app, [*check.split()[1:], "-o", str(tmp_path / "m")])
    assert margins.exit_code == 1 and "UNSTABLE" in margins.output, margins.output
    res = CliRunner().invoke(app, ["export", "--to", "crazyflie", "-c", "crazyflie", "-o", str(tmp_path / "lag"),
                                   "--set", "motors.time_constant=0.03"])
    assert res.exit_code == 0 and "no lag" not in res.stderr, res.output
    # exported with --set, the check is of that design: the command keeps each, quoted for the shell (it named
    # the bundled config's instead)
    res = CliRunner().invoke(app, ["export", "--to", "crazyflie", "-c", "crazyflie", "-o", str(tmp_path / "set"),
                                   "--set", "lqr.roll.R=[2000]", "--set", "simulation.duration=5"])
    assert res.exit_code == 0, res.output
    said = " ".join(res.stderr.split())
    check = ("quadctl margins -c crazyflie --set 'lqr.roll.R=[2000]' --set simulation.duration=5 "
             f"--set motors.time_constant={ROTOR_LAG:g}")
    assert f"before you fly, {check}, and design with it" in said, said


def test_a_setpoint_no_partition_follows_is_refused_naming_only_what_to_regulate():
    """A partition that leaves the yaw free serves no setpoint: the message offers no other --setpoint, only
    regulating, and without --setpoint it says what each setpoint needs (the export of such a design is
    unstable before, so its setup is changed here alone)."""
    from dataclasses import replace

    from quadctl.export import prepare
    from quadctl.setup import setup_of

    exp = prepare(setup_of(config.load("crazyflie")))
    exp = replace(exp, setup=replace(exp.setup, regulated=tuple(s for s in exp.setup.regulated if s != "psi")))
    assert crazyflie.flyable_setpoints(exp) == ()
    with pytest.raises(ConfigError, match=r"so a velocity setpoint cannot be followed: regulate psi \(add them to "
                                          r"a subsystem with regulate: true\)$"):
        crazyflie.check(exp, "velocity")
    # none asked: what each setpoint needs, not a refusal of a position setpoint the user never asked for
    with pytest.raises(ConfigError, match=r"the app can follow none; regulate .*: --setpoint position \(x, y, z, "
                                          r"yaw\) needs pN, pE, psi; --setpoint velocity \(.*\) needs psi$"):
        crazyflie.check(exp)


def test_the_vehicle_is_compared_with_the_firmware_platform_defaults(tmp_path):
    """crazyflie's Förster numbers against the CF 2.1+ defaults: the mass, the maximum thrust and the torque
    coefficient differ (by the percentages of the two sources), the arm agrees; identify is named."""
    from quadctl.export import prepare
    from quadctl.present.platform import platform_sentences
    from quadctl.setup import setup_of

    exp = prepare(setup_of(config.load("crazyflie")))
    rows = {r[0]: r for r in crazyflie_platform.platform_rows(exp)}
    assert rows["mass"][2:4] == (0.027, crazyflie_platform.FIRMWARE.mass)
    text = "\n".join(platform_sentences(crazyflie_platform.platform_rows(exp), crazyflie_platform.FIRMWARE))
    for quantity, key in [("mass", "vehicle.mass"), ("maximum rotor thrust", "motors.max_thrust"),
                          ("torque coefficient", "motors.torque_coefficient")]:
        _, _, mine, theirs, _ = rows[quantity]
        assert f"{quantity}: {key} = " in text and f"({(mine - theirs) / theirs * 100:+.1f} %)" in text
    assert "agrees with the firmware's defaults: arm length" in text
    assert "`quadctl identify`" in text and crazyflie_platform.FIRMWARE.commit[:12] in text
    # the consequence of a larger maximum thrust, in force mode only (force-torque: the firmware mixes and clips)
    assert ("in force mode the firmware clips each rotor at its 0.12 N, where the design's saturation puts it at "
            "0.1592 N" in text)
    torque_mode = "\n".join(platform_sentences(crazyflie_platform.platform_rows(exp), crazyflie_platform.FIRMWARE,
                                               "force-torque"))
    assert "clips" not in torque_mode and "(+32.6 %)" in torque_mode
    # the last sentence holds for an identified config too (it does not tell its user to identify again)
    assert "check that the config's numbers are those of the vehicle you fly" in text
    res = CliRunner().invoke(app, ["export", "--to", "crazyflie", "-c", "crazyflie", "--setpoint", "velocity",
                                   "-o", str(tmp_path / "app"), "--json"])
    assert res.exit_code == 0, res.output
    import json

    got = json.loads(res.stdout)["crazyflie"]
    assert got["calls_per_sample"] == 2 and got["firmware"]["commit"] == crazyflie_platform.FIRMWARE.commit
    assert {r["key"]: r["firmware"] for r in got["platform"]}["motors.max_thrust"] == 0.12


ARM_FLAGS = ["-mcpu=cortex-m4", "-mthumb", "-mfloat-abi=hard", "-mfpu=fpv4-sp-d16", "-Os", "-Wall", "-Wextra",
             "-Werror", "-Wdouble-promotion", "-std=gnu11", "-ffunction-sections", "-fdata-sections"]
"""The Crazyflie firmware's target and warning flags for the Cortex-M4 (its FPU single precision only)."""


@pytest.mark.parametrize("mode", ["force", "force-torque"])
def test_the_app_cross_compiles_for_the_cortex_m4_without_double_precision_calls(tmp_path, mode):
    gcc = shutil.which("arm-none-eabi-gcc")
    if gcc is None:
        pytest.skip("arm-none-eabi-gcc is not installed (Debian: apt-get install gcc-arm-none-eabi; .ci/run "
                    "installs it as root): the cross-compile is not checked here")
    size = shutil.which("arm-none-eabi-size")
    nm = shutil.which("arm-none-eabi-nm")
    cfg = crazyflie_config(tmp_path)
    export_app(cfg, tmp_path / "app", "--setpoint", "velocity", "--mode", mode)
    inc = tmp_path / "firmware"
    inc.mkdir()
    for name, text in FIRMWARE_HEADERS.items():
        (inc / name).write_text(text)
    total = 0
    for name in ("quadctl_controller", "quadctl_crazyflie"):
        obj = tmp_path / f"{name}.o"
        out = subprocess.run([gcc, *ARM_FLAGS, "-DQUADCTL_FLOAT", f"-I{inc}", f"-I{tmp_path / 'app' / 'src'}", "-c",
                              str(tmp_path / "app" / "src" / f"{name}.c"), "-o", str(obj)],
                             capture_output=True, text=True)
        assert out.returncode == 0, out.stderr
        undefined = subprocess.run([nm, "-u", str(obj)], capture_output=True, text=True, check=True).stdout
        assert "__aeabi_d" not in undefined, f"{name}.o calls double-precision helpers:\n{undefined}"
        sizes = subprocess.run([size, str(obj)], capture_output=True, text=True, check=True).stdout.split("\n")[1]
        text, data, bss = (int(v) for v in sizes.split()[:3])
        total += text + data
        print(f"{mode}: {name}.o text {text} B, data {data} B, bss {bss} B")
    print(f"{mode}: the app's controller and adapter: {total} B of flash")
    assert total < 16384  # a few kB on a 1 MB flash


OOT_MK_STAND_IN = """OOT ?= $(PWD)
OOT_CONFIG ?= $(OOT)/oot-config
show:
\t@echo $(OOT) $(OOT_CONFIG) $(EXTRA_CFLAGS)
"""
"""A stand-in for the firmware's tools/make/oot.mk: its defaults (the app's folder from the shell's PWD, the
config beside it) and a target that shows what the firmware's build would be given."""


def test_the_apps_makefile_finds_the_app_when_make_starts_elsewhere(tmp_path):
    """``make -C APP``, or a script's make run in APP with its own PWD, builds the app: the Makefile takes the
    app's folder from make (CURDIR). From the shell's PWD, which neither changes, the firmware built the
    caller's folder without app-config, so without the out-of-tree controller."""
    make = shutil.which("make")
    if make is None:
        pytest.skip("make is not installed: the app's Makefile is not run here")
    export_app(crazyflie_config(tmp_path), tmp_path / "app", "--setpoint", "velocity")
    firmware, elsewhere = tmp_path / "firmware", tmp_path / "elsewhere"
    (firmware / "tools" / "make").mkdir(parents=True)
    (firmware / "tools" / "make" / "oot.mk").write_text(OOT_MK_STAND_IN)
    elsewhere.mkdir()
    res = subprocess.run([make, "--no-print-directory", "-s", "-C", str(tmp_path / "app"),
                          f"CRAZYFLIE_BASE={firmware}", "show"], cwd=elsewhere,
                         env={**os.environ, "PWD": str(elsewhere)}, capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    assert res.stdout.split() == [str(tmp_path / "app"), str(tmp_path / "app" / "app-config"), "-DQUADCTL_FLOAT"]


FIRMWARE_CHECKOUT = "QUADCTL_CRAZYFLIE_FIRMWARE"
"""The environment variable naming a checkout of bitcraze/crazyflie-firmware with its submodules: where it is
set, the app is built inside it."""


def test_the_platform_numbers_are_the_firmware_headers():
    """crazyflie_platform.FIRMWARE's numbers are those its header gives for the default (2.1+) propellers with
    the battery compensation on, as the firmware's floats: read from the checkout, not from quadctl."""
    base = os.environ.get(FIRMWARE_CHECKOUT)
    if not base:
        pytest.skip(f"{FIRMWARE_CHECKOUT} is not set: set it to a crazyflie-firmware checkout to compare the "
                    "platform's numbers with its header")
    fw = crazyflie_platform.FIRMWARE
    text = (Path(base) / fw.source).read_text()
    plus = text[text.index("#if defined(CONFIG_CRAZYFLIE_21_PLUS)"):]
    plus = plus[:plus.index("#elif")]

    def macro(name, where):  # the last definition: CF_MASS's without the thrust upgrade kit
        return np.float32(re.findall(rf"#define\s+{name}\s+([-0-9.eE]+)f", where)[-1])

    want = {"VMOTOR2THRUST0": fw.vmotor2thrust[0], "VMOTOR2THRUST1": fw.vmotor2thrust[1],
            "VMOTOR2THRUST2": fw.vmotor2thrust[2], "VMOTOR2THRUST3": fw.vmotor2thrust[3],
            "THRUST_MIN": fw.min_thrust, "THRUST_MAX": fw.max_thrust, "THRUST2TORQUE": fw.torque_coefficient}
    assert {k: macro(k, plus) for k in want} == {k: np.float32(v) for k, v in want.items()}
    assert macro("ARM_LENGTH", text) == np.float32(fw.arm_length) and macro("CF_MASS", text) == np.float32(fw.mass)


@pytest.mark.slow
def test_the_app_builds_and_links_inside_the_firmware(tmp_path):
    """The firmware's own build (its headers, flags and link) of the exported app, with the arm-none-eabi
    toolchain: the image holds the out-of-tree controller, and no app object calls a double-precision helper."""
    base = os.environ.get(FIRMWARE_CHECKOUT)
    if not base:
        pytest.skip(f"{FIRMWARE_CHECKOUT} is not set: set it to a crazyflie-firmware checkout with its submodules "
                    "to build the app inside the firmware")
    tools = {name: shutil.which(name) for name in ("make", "arm-none-eabi-gcc", "arm-none-eabi-nm")}
    if not all(tools.values()):
        pytest.skip(f"not installed: {', '.join(n for n, p in tools.items() if p is None)} (Debian: apt-get install "
                    "make gcc-arm-none-eabi)")
    assert (Path(base) / "tools" / "make" / "oot.mk").is_file(), f"{FIRMWARE_CHECKOUT}={base}: no tools/make/oot.mk"
    app_dir = tmp_path / "app"
    export_app(crazyflie_config(tmp_path), app_dir, "--setpoint", "velocity")
    res = subprocess.run([tools["make"], f"-j{os.cpu_count() or 1}", f"CRAZYFLIE_BASE={base}"], cwd=app_dir,
                         capture_output=True, text=True, timeout=1800)
    assert res.returncode == 0, res.stdout[-4000:] + res.stderr[-4000:]
    assert "CONFIG_CONTROLLER_OOT=y" in (app_dir / "build" / ".config").read_text().splitlines()
    assert (app_dir / "build" / "cf2.bin").is_file()
    nm = tools["arm-none-eabi-nm"]
    defined = subprocess.run([nm, "--defined-only", str(app_dir / "build" / "cf2.elf")], capture_output=True,
                             text=True, check=True).stdout.split()
    for symbol in ("controllerOutOfTree", "controllerOutOfTreeInit", "controllerOutOfTreeTest", "quadctl_step_ref"):
        assert symbol in defined, f"cf2.elf does not define {symbol}"
    for obj in sorted((app_dir / "src").glob("quadctl_*.o")):
        undefined = subprocess.run([nm, "-u", str(obj)], capture_output=True, text=True, check=True).stdout
        assert "__aeabi_d" not in undefined, f"{obj.name} calls double-precision helpers:\n{undefined}"


def test_the_c_header_gives_the_trim_as_macros_and_quadctl_trim(tmp_path):
    """The trim is in the header as numbers a program can use (not only a comment): the macros and
    quadctl_trim() give crazyflie's hover at 1 m (pD = -1) and its trim thrust m g."""
    res = CliRunner().invoke(app, ["export", "--to", "c", "-c", "crazyflie", "-o", str(tmp_path)])
    assert res.exit_code == 0, res.output
    (tmp_path / "main.c").write_text(r"""
#include <stdio.h>
#include "quadctl_controller.h"
int main(void) {
  quadctl_real x[QUADCTL_NX], u[QUADCTL_NU];
  const quadctl_real x0[QUADCTL_NX] = QUADCTL_TRIM_X_INIT, u0[QUADCTL_NU] = QUADCTL_TRIM_U_INIT;
  int i;
  quadctl_trim(x, u);
  for (i = 0; i < QUADCTL_NX; ++i) if (x[i] != x0[i]) return 1;
  for (i = 0; i < QUADCTL_NU; ++i) if (u[i] != u0[i]) return 1;
  printf("%.17g %.17g %.17g\n", QUADCTL_TRIM_X_PD, QUADCTL_TRIM_U_T, QUADCTL_RATE_X_PN);
  return 0;
}
""")
    exe = tmp_path / "main"
    out = subprocess.run([compiler(), "-std=c99", "-Wall", "-Wextra", "-pedantic", "-Werror", f"-I{tmp_path}",
                          str(tmp_path / "main.c"), str(tmp_path / "quadctl_controller.c"), "-lm", "-o", str(exe)],
                         capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    run = subprocess.run([str(exe)], capture_output=True, text=True)
    assert run.returncode == 0
    pD, T, rate = (float(v) for v in run.stdout.split())
    cfg = config.load("crazyflie")
    assert pD == -1.0 and rate == 0.0
    assert T == pytest.approx(cfg.vehicle.mass * cfg.vehicle.gravity, rel=1e-9)


def test_the_app_is_whole_and_states_its_licence(tmp_path):
    """The files the firmware's out-of-tree build reads, each generated file under MIT, and a README
    with the two commands that build and flash it; nothing of the firmware's code in it."""
    out = tmp_path / "app"
    export_app(crazyflie_config(tmp_path), out, "--setpoint", "velocity")
    files = sorted(p.relative_to(out).as_posix() for p in out.rglob("*") if p.is_file())
    assert files == sorted([*crazyflie.APP_FILES, "src/quadctl_controller.c", "src/quadctl_controller.h",
                            artifacts.MARK_NAME,  # the mark: quadctl may write this folder again
                            "config.yaml", "config.resolved.yaml"])  # the config that made it
    for name in ("Makefile", "src/quadctl_app.c", "src/quadctl_crazyflie.c", "src/quadctl_crazyflie.h"):
        assert "SPDX-License-Identifier: MIT" in (out / name).read_text(), name
    readme = (out / "README.md").read_text()
    assert "make -j CRAZYFLIE_BASE=" in readme and "make cload CRAZYFLIE_BASE=" in readme and "MIT" in readme
    assert "CONFIG_CONTROLLER_OOT=y" in (out / "app-config").read_text()
    assert "include $(CRAZYFLIE_BASE)/tools/make/oot.mk" in (out / "Makefile").read_text()
    src = (out / "src" / "quadctl_crazyflie.c").read_text()
    gpl_header = ("Bitcraze" + " AB", "GNU General" + " Public License")  # the firmware's file header (GPL-3.0)
    assert not any(words in src for words in gpl_header)


def test_the_apps_law_line_names_the_commanders_setpoints_as_its_reference(tmp_path):
    """export --to crazyflie printed the law with "the reference flown (simulation.reference) ... (the
    differential-flatness trim along the path)": the app follows the commander's setpoints about the hover
    trim, as the line before it says."""
    res = CliRunner().invoke(app, ["export", "--to", "crazyflie", "-c", "crazyflie", "-o", str(tmp_path / "app")])
    assert res.exit_code == 0, res.output
    law = " ".join(next(line for line in res.stdout.splitlines() if line.startswith("law: ")).split())
    assert "the reference flown (the commander's velocity setpoints, through the app's adapter)" in law
    assert "(the hover trim's roll, pitch and input)" in law and "simulation.reference" not in law
