"""Every public function that takes matrices checks their shape and dtype and names the argument
(SciPy's ``_are_validate_args``), through one helper (:func:`quadctl.design.riccati.real_array`): quadctl's
solvers are real-only, and say so, rather than drop an imaginary part and certify another problem."""

from __future__ import annotations

import math
import warnings
from types import SimpleNamespace

import numpy as np
import pytest

import quadctl as qc
from quadctl.design import closed_loop_matrix, discrete, lqr, riccati
from quadctl.errors import ArgumentError
from quadctl.export import interop
from quadctl.layout import INPUT_NAMES, STATE_NAMES

A_SCIPY = np.array([[2, 1 - 2j], [0, -3j]])
"""SciPy's own complex DARE test case (scipy/linalg/tests/test_solvers.py, solve_discrete_are)."""
B2, Q2, R2 = np.eye(2), np.eye(2), np.eye(2)
COMPLEX = "is complex .*quadctl solves real problems only"


@pytest.fixture(autouse=True)
def _no_complex_warning():
    """A ComplexWarning (an imaginary part silently dropped) fails the test."""
    with warnings.catch_warnings():
        warnings.simplefilter("error", np.exceptions.ComplexWarning)
        yield


ONE = {
    "lqr": lambda A, B: lqr(A, B, Q2, R2),
    "dlqr": lambda A, B: discrete.dlqr(A, B, Q2, R2),
    "lqrd": lambda A, B: discrete.lqrd(A, B, Q2, R2, 0.01),
    "riccati.solve": lambda A, B: riccati.solve(A, B, Q2, R2, discrete=True),
    "care_schur": lambda A, B: riccati.care_schur(A, B, Q2, R2),
    "c2d": lambda A, B: discrete.c2d(A, B, 0.01),
    "lqrd_weights": lambda A, B: discrete.lqrd_weights(A, B, Q2, R2, 0.01),
    "riccati_residual": lambda A, B: riccati.riccati_residual(A, B, Q2, R2, Q2),
    "dare_residual": lambda A, B: riccati.dare_residual(A, B, Q2, R2, Q2),
    "closed_loop_matrix": lambda A, B: closed_loop_matrix(A, B, np.zeros((2, 2))),
    "LqrdWeightMap": lambda A, B: discrete.LqrdWeightMap(A, B, 0.01),
}
BATCH = {
    "care_batch": lambda A, B: riccati.care_batch(A, B, Q2[None], R2[None]),
    "dare_batch": lambda A, B: riccati.dare_batch(A, B, Q2[None], R2[None]),
    "c2d_batch": lambda A, B: discrete.c2d_batch(A, B, 0.01),
    "lqrd_weights_batch": lambda A, B: discrete.lqrd_weights_batch(A, B, Q2[None], R2[None], 0.01),
    "riccati_residuals": lambda A, B: riccati.riccati_residuals(A, B, Q2[None], R2[None], Q2[None]),
    "dare_residuals": lambda A, B: riccati.dare_residuals(A, B, Q2[None], R2[None], Q2[None]),
}


@pytest.mark.parametrize("solver", ONE)
def test_a_complex_a_is_refused_by_name_not_solved_as_another_problem(solver):
    with pytest.raises(ArgumentError, match=rf": A {COMPLEX}"):
        ONE[solver](A_SCIPY, B2)


@pytest.mark.parametrize("solver", ONE)
def test_a_complex_b_with_zero_real_part_is_refused_as_complex_not_unstabilizable(solver):
    with pytest.raises(ArgumentError, match=rf": B {COMPLEX}"):
        ONE[solver](np.diag([0.5, -0.5]), 1j * B2)


@pytest.mark.parametrize("solver", BATCH)
def test_the_batched_solvers_refuse_complex_stacks(solver):
    with pytest.raises(ArgumentError, match=rf"^{solver}: A {COMPLEX}"):
        BATCH[solver](A_SCIPY[None], B2[None])


@pytest.mark.parametrize("bad, match", [
    (np.array([["1", "2"], ["3", "4"]]), "A is not a numeric matrix"),
    (np.array([[1, None], [0, 1]], dtype=object), "A is not a numeric matrix"),
    ([[1, 2], [3]], "A is not a numeric matrix"),
])
def test_text_objects_and_ragged_lists_are_no_matrices(bad, match):
    with pytest.raises(ArgumentError, match=match):
        lqr(bad, B2, Q2, R2)


def test_the_real_problem_still_solves_to_scipys_answer():
    """The check refuses only what it must: the real part of SciPy's case solves as SciPy does."""
    from scipy.linalg import solve_discrete_are

    A = A_SCIPY.real
    K, P, _ = discrete.dlqr(A, B2, Q2, R2)
    np.testing.assert_allclose(P, solve_discrete_are(A, B2, Q2, R2), rtol=1e-10)


# ---------------------------------------------------------------------------------------
# quadctl.export.interop


def _design(K=None, Ki=None, ints=()):
    return SimpleNamespace(K_block=np.zeros((4, 12)) if K is None else K, Ki_block=Ki, integral_states=ints,
                           sample_time=None)


def _linear(A=None, B=None):
    return SimpleNamespace(A=np.zeros((12, 12)) if A is None else A, B=np.zeros((12, 4)) if B is None else B)


INTEROP = {
    "closed_loop K 3x12": (lambda: interop.closed_loop(_linear(), _design(np.zeros((3, 12)))),
                           r"^interop: design\.K_block has shape \(3, 12\), expected 4 x 12$"),
    "closed_loop complex A": (lambda: interop.closed_loop(_linear(A=np.eye(12) * 1j), _design()),
                              rf"^closed_loop: A {COMPLEX}"),
    "closed_loop B 12x3": (lambda: interop.closed_loop(_linear(B=np.zeros((12, 3))), _design()),
                           r"^closed_loop: linear\.B has shape \(12, 3\), expected 12 x 4$"),
    "closed_loop sample_time inf": (lambda: interop.closed_loop(_linear(), _design(), sample_time=math.inf),
                                    r"^closed_loop: sample_time = inf: must be a positive finite number"),
    "controller Ki wrong": (lambda: interop.controller(_design(Ki=np.zeros((4, 2)), ints=("pD",))),
                            r"^interop: design\.Ki_block has shape \(4, 2\), expected 4 x 1$"),
    "controller unknown state": (lambda: interop.controller(_design(Ki=np.zeros((4, 1)), ints=("height",))),
                                 r"^interop: design\.integral_states names 'height', not a state"),
    "controller complex K": (lambda: interop.controller(_design(np.zeros((4, 12), complex))),
                             rf"^interop: design\.K_block {COMPLEX}"),
    "controller sample_time -1": (lambda: interop.controller(_design(), sample_time=-1.0),
                                  r"^controller: sample_time = -1\.0: must be a positive finite number"),
    "plant complex B": (lambda: interop.plant(_linear(B=np.zeros((12, 4), complex))), rf"^plant: B {COMPLEX}"),
    "plant A 11x12": (lambda: interop.plant(_linear(A=np.zeros((11, 12)))),
                      r"^plant: A has shape \(11, 12\), expected 11 x 11$"),
    "plant 2 states": (lambda: interop.plant(_linear(A=np.zeros((2, 2)), B=np.zeros((2, 4)))),
                       r"^plant: linear\.A has shape \(2, 2\), expected 12 x 12$"),
    "plant sample_time nan": (lambda: interop.plant(_linear(), sample_time=math.nan),
                              r"^plant: sample_time = nan: must be a positive finite number"),
    "subsystem C wrong": (lambda: interop.subsystem(SimpleNamespace(
        A=np.zeros((2, 2)), B=np.zeros((2, 1)), C=np.zeros((1, 3)), states=("pD", "w"), inputs=("T",), name="s")),
        r"^subsystem: sub\.C has shape \(1, 3\), expected \? x 2$"),
    "subsystem states": (lambda: interop.subsystem(SimpleNamespace(
        A=np.zeros((2, 2)), B=np.zeros((2, 1)), C=np.eye(2), states=("pD",), inputs=("T",), name="s")),
        r"^subsystem: A is 2 x 2 and B has 1 columns for 1 states and 1 inputs$"),
    "from_statespace complex": (lambda: interop.from_statespace(SimpleNamespace(
        A=A_SCIPY, B=B2, state_labels=["a", "b"], input_labels=["u", "v"], dt=0)),
        rf"^from_statespace: sys\.A {COMPLEX}"),
    "Plant.lqr complex": (lambda: interop.Plant(A=A_SCIPY, B=B2, state_names=("a", "b"), input_names=("u", "v"),
                                                dt=0.1).lqr(Q2, R2), rf"^plant: A {COMPLEX}"),
    "design not a design": (lambda: interop.controller(object()),
                            r"^design must be a quadctl\.design\.Design or a quadctl\.sim\.loop\.ClosedLoop"),
}


@pytest.mark.parametrize("case", INTEROP)
def test_every_interop_function_names_the_argument_it_refuses(case):
    pytest.importorskip("control")
    call, match = INTEROP[case]
    with pytest.raises((ValueError, TypeError), match=match):
        call()


def test_interop_accepts_what_quadctl_designs(forward):
    control = pytest.importorskip("control")
    _, _, linear, _, design = forward
    sys = interop.closed_loop(linear, design)
    assert isinstance(sys, control.StateSpace) and sys.nstates == 12
    assert list(sys.input_labels) == list(INPUT_NAMES) and list(sys.state_labels) == list(STATE_NAMES)


# ---------------------------------------------------------------------------------------
# The export API


def test_the_export_writer_names_a_target_it_does_not_know(tmp_path):
    from quadctl import export

    with pytest.raises(ValueError, match=r"^to must be one of \('c', 'mat', 'json', 'crazyflie'\), got 'pdf'$"):
        export.write(SimpleNamespace(), "pdf", tmp_path)
    assert not any(tmp_path.iterdir())


@pytest.mark.parametrize("who", ["write", "files", "sources", "fields", "mat_variables", "json_payload", "write_mat"])
def test_the_export_writers_name_an_argument_that_is_no_export(tmp_path, who):
    import io

    from quadctl import export
    from quadctl.export import c as cexport
    from quadctl.export import data

    calls = {"write": lambda x: export.write(x, "json", tmp_path), "files": lambda x: export.files(x, "c", tmp_path),
             "sources": cexport.sources, "fields": data.fields,
             "mat_variables": data.mat_variables, "json_payload": data.json_payload,
             "write_mat": lambda x: data.write_mat(io.BytesIO(), x)}
    name = "mat_variables" if who == "write_mat" else who
    with pytest.raises(TypeError, match=rf"^{name}: exp must be a quadctl\.export\.Export \(from "
                                        r"quadctl\.export\.prepare\), got dict$"):
        calls[who]({"K": np.zeros((4, 12))})
    assert not any(tmp_path.iterdir())


def test_a_c_export_of_a_continuous_design_is_refused(forward):
    from quadctl import export
    from quadctl.export import c as cexport

    exp = export.prepare(forward[0], need_rate=False)
    with pytest.raises(ValueError, match="a C controller samples: prepare the export with a rate"):
        cexport.sources(exp)


# ---------------------------------------------------------------------------------------
# Every wrong argument of a public call is a QuadctlError and the builtin a SciPy user expects


@pytest.fixture(scope="module")
def hover():
    """The hover config's stages (a continuous design, no schedule, no reference), computed once."""
    return qc.Stages(qc.setup_of(qc.load_config("hover")))


def _sweep_run_of_a_name(tmp_path, stages):
    from quadctl import sweep

    return sweep.run("forward", None, jobs=1)


def _sweep_run_of_a_mapping(tmp_path, stages):
    from quadctl import sweep

    return sweep.run(qc.load_config("forward"), {"parameters": {"vehicle.mass": [0.06, 0.07]}}, jobs=1)


def _export_files_of_a_mapping(tmp_path, stages):
    from quadctl import export

    return export.files({"K": np.zeros((4, 12))}, "c", tmp_path)


def _export_prepare_of_the_stages(tmp_path, stages):
    """The Stages docstring said prepare takes it as it is: an AttributeError ('Stages' object has no
    attribute 'law')."""
    from quadctl import export

    return export.prepare(stages)


def _export_write_to_pdf(tmp_path, stages):
    from quadctl import export

    return export.write(SimpleNamespace(), "pdf", tmp_path)


def _read_a_missing_log(tmp_path, stages):
    from quadctl.identify.readers import read_log

    return read_log(tmp_path / "flight.csv")


def _identify_with_a_configs_name(tmp_path, stages):
    from quadctl.identify.results import identify

    return identify([], "crazyflie")


def _compare_an_unknown_law(tmp_path, stages):
    from quadctl.compare import compare

    return compare(stages, ["pid:betaflight"])


def _transition_without_a_schedule(tmp_path, stages):
    from quadctl.schedule.transition import fly_transition

    return fly_transition(stages.setup)


def _stack_of_a_short_start(tmp_path, stages):
    from quadctl.sim.stack import simulate_stack

    return simulate_stack([stages.loop], [[0.0] * 3], 1.0)


def _gain_table_of_one_value(tmp_path, stages):
    from quadctl.design.gain_table import GainTable

    return GainTable.of("speed", [0.0], np.zeros((1, 4, 12)))


def _pid_preset_unknown(tmp_path, stages):
    from quadctl.config.pid import resolve

    return resolve("betaflight")


def _linear_part_without_jacobians(tmp_path, stages):
    from dataclasses import replace

    return replace(stages.loop, jacobians=None).linear_part()


def _closed_loop_of_without_integrators(tmp_path, stages):
    from dataclasses import replace

    from quadctl import pipeline

    setup = replace(stages.setup, integral={"altitude": ("pD",)})
    return pipeline.closed_loop_of(setup, stages.linear, stages.design.K_block)


ARGUMENTS = {  # a call with a wrong argument: (call(tmp_path, stages), its class, the builtin, the message)
    "simulate negative duration": (
        lambda _, s: qc.simulate(s.loop, s.loop.x_trim, -1.0),
        "ArgumentError", ValueError, r"^duration must be a positive number of seconds, got -1\.0$"),
    "simulate dt text": (
        lambda _, s: qc.simulate(s.loop, s.loop.x_trim, 1.0, dt="fast"),
        "ArgumentError", ValueError, r"^dt must be a positive number of seconds or 'auto', got 'fast'$"),
    "simulate unknown method": (
        lambda _, s: qc.simulate(s.loop, s.loop.x_trim, 1.0, method="euler"),
        "ArgumentError", ValueError, r"^method must be 'rk4' or 'etdrk4', got 'euler'$"),
    "simulate a design": (
        lambda _, s: qc.simulate(s.design, s.loop.x_trim, 1.0),
        "ArgumentTypeError", TypeError, r"^simulate takes a ClosedLoop, stages\.loop of .*; got Design$"),
    "simulate_stack x0 of 3": (
        _stack_of_a_short_start,
        "ArgumentError", ValueError, r"^x0 must be the 12 states pN, pE, .*, got shape \(3,\)$"),
    "lqr A None": (
        lambda _, s: qc.lqr(None, [[1.0]], [[1.0]], [[1.0]]),
        "ArgumentError", ValueError, r"^system: A is None; give an array of numbers$"),
    "dlqr 1-D B": (
        lambda _, s: qc.dlqr(np.eye(2), [0.0, 1.0], np.eye(2), [[1.0]]),
        "ArgumentError", ValueError, r"^system: B has shape \(2,\), a 1-D array read as the row \(1, 2\)"),
    "lqrd negative Ts": (
        lambda _, s: qc.lqrd([[0.0]], [[1.0]], [[1.0]], [[1.0]], -0.01),
        "ArgumentError", ValueError, r"^system: Ts = -0\.01: the sample time must be a positive finite number of "
                                     r"seconds$"),
    "c2d Ts text": (
        lambda _, s: discrete.c2d([[0.0]], [[1.0]], "fast"),
        "ArgumentError", ValueError, r"^c2d: Ts = 'fast': the sample time must be a positive finite number of "
                                     r"seconds$"),
    "load_config a dict": (
        lambda _, s: qc.load_config({"name": "mine"}),
        "ArgumentTypeError", TypeError, r"^load_config takes a file path or a bundled config's name, got dict; "
                                        r"validate a mapping with quadctl\.config\.from_dict\(data\)$"),
    "setup_of a name": (
        lambda _, s: qc.setup_of("hover"),
        "ArgumentTypeError", TypeError, r"^setup_of takes a validated Config, .*; got str$"),
    "Stages a config": (
        lambda _, s: qc.Stages(qc.load_config("hover")),
        "ArgumentTypeError", TypeError, r"^Stages takes a Setup, .*; got Config$"),
    "initial_state of 5": (
        lambda _, s: s.setup.initial_state([0.0] * 5),
        "ArgumentError", ValueError, r"^initial_state takes the 12 states of a trim .*, got shape \(5,\)$"),
    "Vehicle negative mass": (
        lambda _, s: qc.Vehicle(mass=-1.0),
        "ArgumentError", ValueError, r"^Vehicle: mass \(kg\) and the inertia's diagonal \(kg m\^2\) must be positive, "
                                     r"got mass -1\.0"),
    "margins delay of a continuous design": (
        lambda _, s: qc.margins(s.design, s.decoupled, s.linear.A, s.linear.B, delay_samples=1),
        "ArgumentError", ValueError, r"^margins: delay_samples = 1 of a continuous design: a delay is counted in "
                                     r"controller samples; give emulated_rate \(Hz\), or a design at a rate$"),
    "sweep.run a name": (
        _sweep_run_of_a_name,
        "ArgumentTypeError", TypeError, r"^sweep\.run takes a validated Config, .*; got str$"),
    "sweep.run a mapping": (
        _sweep_run_of_a_mapping,
        "ArgumentTypeError", TypeError, r"^sweep\.run takes a SweepSpec, sweep\.from_dict\(data, cfg\) .*; got dict$"),
    "export.files a mapping": (
        _export_files_of_a_mapping,
        "ArgumentTypeError", TypeError, r"^files: exp must be a quadctl\.export\.Export \(from quadctl\.export\."
                                        r"prepare\), got dict$"),
    "export.prepare the stages": (
        _export_prepare_of_the_stages,
        "ArgumentTypeError", TypeError, r"^prepare takes a Setup, export\.prepare\(stages\.setup\) or "
                                        r"export\.prepare\(qc\.setup_of\(cfg\)\); got Stages$"),
    "export.write to pdf": (
        _export_write_to_pdf,
        "ArgumentError", ValueError, r"^to must be one of \('c', 'mat', 'json', 'crazyflie'\), got 'pdf'$"),
    "interop.from_statespace an object": (
        lambda _, s: interop.from_statespace(object()),
        "ArgumentTypeError", TypeError, r"^from_statespace: expected a control\.StateSpace, got object; convert it "
                                        r"with control\.ss\(sys\)$"),
    "interop.plant a config's name": (
        lambda _, s: interop.plant("hover"),
        "ArgumentTypeError", TypeError, r"^plant: linear must be a quadctl\.linear\.linearize\.LinearModel, "
                                        r"stages\.linear; got str$"),
    "interop.subsystem a design": (
        lambda _, s: interop.subsystem(s.design),
        "ArgumentTypeError", TypeError, r"^subsystem: sub must be a quadctl\.linear\.decouple\.Subsystem, .*; "
                                        r"got Design$"),
    "interop.closed_loop the design twice": (
        lambda _, s: interop.closed_loop(s.design, s.design),
        "ArgumentTypeError", TypeError, r"^closed_loop: linear must be a quadctl\.linear\.linearize\.LinearModel, "
                                        r"stages\.linear; got Design$"),
    "identify a missing log": (
        _read_a_missing_log,
        "LogError", ValueError, r"flight\.csv: no such file; give the path of a flight log$"),
    "identify a config's name": (
        _identify_with_a_configs_name,
        "ArgumentTypeError", TypeError, r"^identify takes a validated Config, .*; got str$"),
    "compare an unknown law": (
        _compare_an_unknown_law,
        "ArgumentError", ValueError, r"^law 'pid:betaflight': use lqr or pid:<preset> with a preset of crazyflie, "
                                     r"px4$"),
    "resolve an unknown PID preset": (
        _pid_preset_unknown,
        "ArgumentError", ValueError, r"^unknown PID preset 'betaflight': use one of crazyflie, px4$"),
    "fly_transition without a schedule": (
        _transition_without_a_schedule,
        "ArgumentError", ValueError, r"^fly_transition: the setup has no schedule \(schedule:\): a transition flies"),
    "GainTable.of one value": (
        _gain_table_of_one_value,
        "ArgumentError", ValueError, r"^GainTable\.of: values = \[0\.0\]: a gain table needs at least two finite "
                                     r"scheduling values"),
    "linear_part without jacobians": (
        _linear_part_without_jacobians,
        "ArgumentError", ValueError, r"^this ClosedLoop has no jacobians \(A, B\): build it with "
                                     r"quadctl\.pipeline\.closed_loop_of$"),
    "closed_loop_of without integrators": (
        _closed_loop_of_without_integrators,
        "ArgumentError", ValueError, r"^closed_loop_of: no integral_states, and the setup has integral action"),
}


@pytest.mark.parametrize("case", ARGUMENTS)
def test_a_wrong_argument_is_a_quadctl_error_and_the_builtin_a_scipy_user_catches(case, hover, tmp_path):
    """``except qc.QuadctlError`` and ``except ValueError`` (or ``TypeError``) both catch it, and the one line
    names the argument, what was expected and what was found."""
    from quadctl import errors

    call, cls, builtin, match = ARGUMENTS[case]
    with pytest.raises(qc.QuadctlError, match=match) as info:
        call(tmp_path, hover)
    assert type(info.value) is getattr(errors, cls)
    assert isinstance(info.value, builtin)
    assert "\n" not in str(info.value)
    assert not any(tmp_path.iterdir())  # refused before anything is written


@pytest.mark.parametrize("cls, builtin", [("ArgumentError", ValueError), ("ArgumentTypeError", TypeError)])
def test_an_argument_error_is_bad_input_to_the_command_line(cls, builtin):
    """Exit code 2 (bad input, the folder put back), as a config error: not 1 (a check failed) nor a bug's 3."""
    error = getattr(qc, cls)
    assert issubclass(error, qc.QuadctlError) and issubclass(error, builtin)
    assert error.exit_code == 2 and not error.from_config
    assert not issubclass(error, (ValueError if builtin is TypeError else TypeError))
