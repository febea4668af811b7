"""The engine's tuning constants, in one place: the defaults of every choice the periodic
engine makes that is not mathematics (issue 37).

Each constant is documented where it is defined below, with the measurement that set it,
and each is the default of one field of ``EngineOptions``, the options passed through the
kernels at run time by role: the step-size controller's (``ControlOptions``), one point's
solve's (``PointOptions``), the turning-point traps' (``TrapOptions``), the kinematic
stops' (``StopOptions``), the state events' (``EventOptions``), the step lengths'
(``StepOptions``), the stage solve's (``StageOptions``), the defect estimate's
(``DefectOptions``), the tolerances' factors (``ToleranceOptions``) and the batches'
(``BatchOptions``).  ``solve_periodic(..., options=EngineOptions(...))`` changes them
without recompiling (one compiled signature for every value); no other module reads them
as globals (``tests/test_engine_options.py``).  ``engine_options()`` lists the values of
an ``EngineOptions``, for provenance; ``SolveResult.options`` holds those a solve used.

What defines the method rather than tunes it keeps its own module: the Radau IIA tableau
(``periodic.radau``), the defect estimate's two samples and its quadrature rule
(``periodic.defect``), the step record's layout (``periodic.record``) and the codes of
stops, events and statuses; the tolerances are derived from rtol in ``periodic.tolerances``.
"""
from __future__ import annotations

from typing import NamedTuple


def engine_options(options=None) -> dict:
    """{"role.name": value} of every field of ``options`` (an EngineOptions; None: the
    defaults), for provenance."""
    options = DEFAULT_OPTIONS if options is None else options
    return {f"{role}.{name}": value for role, group in zip(options._fields, options)
            for name, value in zip(group._fields, group)}


# ------------------------------------------------ the stage solve (``periodic.radau.radau5_step``)
#: the stage Newton gives up (the step is retried, ``periodic.steps.solve_step``) after this
#: many iterations
MAX_STAGE_ITERATIONS = 40
#: Newton's first correction is taken as the last where the quadratic constant carried from
#: the previous step predicts the next correction below this share of the tolerance
#: (``radau5_step``'s ``rate``).  A prediction, not a bound (stages up to 3.7e5 atol off were
#: measured), so ``periodic.integrator.adaptive_pass`` uses it in the loose passes only (bench: 857 ->
#: 601 evaluations per solve there; docs/validation.md)
FIRST_CORRECTION_SHARE = 0.1
#: ... and only where dF/du at the predicted stages is within this share of ``slope``
SLOPE_SHARE = 0.25

# ------------------------------------------------------- the defect estimate (``periodic.defect``)
#: (its two samples, THETA_MID and THETA_LATE, are the estimator's definition, as the Radau
#: nodes are the step's: they fix its 6-point quadrature rule, computed from them once, and
#: are not a tuning; they live in ``periodic.defect``)
#: the defect estimate moves by about this many times a change of the stage values (the
#: polynomial's slope at the start, divided by h, times h): its floor is this times the
#: stages' error (the Newton tolerance plus rounding), which no smaller step reduces
NOISE_GAIN = 16.0
#: the defect divided by the stages' node polynomial, linear through the start and THETA_MID,
#: must predict the late sample within this share of it; else the step's solution is not in
#: the asymptotic regime and the embedded estimate (conservative) is used
DEFECT_FIT = 0.5
#: up to this |h kappa dF/du| the resolvent of the defect estimate is integrated with the
#: slope varying along the step (8-point Gauss-Legendre: ~1e-3 relative at the limit)
VARIABLE_SLOPE_LIMIT = 16.0

# ------------------------------------------------- the step-size controller (``periodic.control``)
#: the factor is multiplied by this (a step sized exactly at the tolerance fails half the time)
SAFETY = 0.9
#: smallest and largest change of the step size from one step to the next (MAX_FACTOR 6:
#: 23 % of the target pass's attempts were rejected, most right after a step whose error
#: sat below the noise floor, which asks for the largest growth; 3: bench evaluations per
#: solve 2,803 -> 2,571 at rtol 1e-4, 8,129 -> 7,669 at 1e-7; its earlier worst case was
#: a missed int u error of ``periodic.defect.defect_error``, since fixed; docs/validation.md)
MIN_FACTOR = 0.2
MAX_FACTOR = 3.0

# -- step lengths and the period integrator's loop (``periodic.steps``, ``periodic.integrator``)
#: the smallest step (in tau, period 1): below it a pass fails (TOLERANCE_NOT_REACHED)
MIN_STEP = 2.0 ** -40
#: a step this short is accepted whatever its error (which the estimate counts): next to a
#: power law's corner omega ~ z^(gamma - 1), and for gamma near 1 (1.035 measured) the error
#: per unit length does not fall as steps shrink, so no step size meets it: the steps
#: approached the corner geometrically down to MIN_STEP and the pass failed
ACCEPT_STEP = 2.0 ** -36
#: a step whose defect model does not fit (``periodic.defect.defect_error``) is judged by this many
#: times its error estimate (measured: the fallback estimates were up to 12x too small next
#: to turning points at scaled period 0.01)
FIT_DISTRUST = 16.0
#: a step is stretched to a stop within this factor of it, and split evenly up to twice it
STRETCH = 1.25
#: a pass gives up after this many attempted steps per accepted one (plus 16)
MAX_ATTEMPTS_PER_STEP = 32

# ------------------------------------- state events (``periodic.events``, ``periodic.estimators``)
#: a state event closer than this share of its step to the step's end is taken to be on it
EVENT_END_SHARE = 1e-6
#: ... and one closer than this share of the previous step to the step's start is not cut:
#: mostly it is the one that step ended at (located on its polynomial, then missed by the
#: re-solved step by a residue; cut there, steps of 1e-7 .. 1e-8 followed, grown back by
#: MAX_FACTOR over 5-7 steps: bench, rtol 1e-4, median n_tau 116 -> 105 with this share
#: instead of 1e-6), but after a kinematic stop it can be another event (a reviewer: 196 of
#: ~17.8k skipped), which then stays inside its step, judged by the error estimate (no
#: solve's error changed against the share 1e-6 on 7 sets x 150 points x 4 rtols)
EVENT_START_SHARE = 1e-3
#: state switching functions within this share of their terms' size have no sign
SIGN_ROUNDING = 64.0 * 2.0 ** -52
#: a switching function's value has a sign beyond this many stage tolerances
EVENT_NOISE = 8.0
#: ... and a sign change is an event where its sides differ by more than this many delta_tau
CROSSING_BAND = 4.0
#: the friction's band: the body is at rest where |g| is within this many delta_tau (stops)
EVENT_BAND = 10.0
#: an event is cut at most this many times in a row (the located root moves as the step
#: shrinks; past this it is accepted where the last cut put it)
MAX_EVENT_CUTS = 4
#: a state event within this share of a recorded step's end counts as on it (rounding)
SPLIT_SHARE = 1e-9

# -------------------------------------------------------- turning-point traps (``periodic.traps``)
#: next to a turning point of phi a step may change u by friction at most this share of u
#: (``trap_ceiling``)
TRAP_SHARE = 0.1
#: ... but at a simple turning point (``periodic.switching.SIMPLE_TURNING``: a simple zero of omega,
#: no corner) never below this step: where the body comes to rest at the turning point with
#: the links (u -> 0 there) the cap shrinks with u and the steps approached the turning point
#: geometrically (45 % of the bench's steps at rtol 1e-4).  An empirical floor, not a bound:
#: measured honest on the harness's sets (also at 1e-2: worst 2.3 rtol) and a reviewer's
#: short- and long-period harmonic sets; at every turning point it was 6.4 rtol off (estimate
#: 0.6) on a sin^3 Fourier motion whose flat inflections are near-tangencies
#: (``test_a_flat_inflection_keeps_the_trap_cap``), which keep the cap
TRAP_FLOOR = 1e-3
#: at the converged solution a step next to a turning point may exceed its ``trap_ceiling``
#: by this factor before the round is rejected (the shooting's last shift moves u a little)
TRAP_SLACK = 2.0
#: ... and its ceiling, which the next pass keeps over the whole recorded step
#: (``WeightModel.max_step``), splits the step into at most this many: the step next to the
#: turning point gets the cap from that pass's own ``trap_limit`` (from the converged u(0),
#: where its u is the converged one).  The cap itself as the ceiling split a step of 0.014
#: next to a flat turning point into steps of 4.5e-9 (u there 9e-8, in the friction's band):
#: STEP_BUDGET_EXCEEDED after 4,000
#: (``tests/test_engine.py::test_a_trapped_step_is_split_into_at_most_trap_span_steps``)
TRAP_SPAN = 64.0

# -------------------------------------------------------- kinematic stops (``periodic.switching``)
#: samples per wavenumber (and period) in the search for the zeros of the kinematic
#: switching functions of a Fourier motion (a function of wavenumber K has at most 2K zeros)
SAMPLES_PER_WAVENUMBER = 64
#: a minimum of |omega| below this share of max |omega| is a near-tangency (a stop)
TANGENCY_SHARE = 0.1
#: a turning point is simple where |omega'| >= this share of 2 pi max |omega| (``turning_stops``)
SIMPLE_SHARE = 0.5
#: two stops closer than this are one
STOP_GAP = 1e-12

# ------------------------------------------ the root finder (``periodic.switching.illinois_root``)
#: a kinematic stop is located to this share of tau (about two ulps: the stops are found once
#: per point), in at most this many iterations
KINEMATIC_ROOT_SHARE = 4e-16
KINEMATIC_ROOT_ITERATIONS = 200
#: a state event and a held body's exit are located to this share of their step (state
#: events, theta in [0, 1]) or of tau (exits), in at most this many iterations
EVENT_ROOT_SHARE = 1e-13
EVENT_ROOT_ITERATIONS = 100

# ------------------------------------ the global estimate's refinement (``periodic.global_error``)
#: a refinement ceiling is at most this factor below its step (the next pass's own control
#: and the trap caps may still shrink it further).  A share far above the tolerance says that
#: the step's estimate left its asymptotic regime, not how much smaller the step must be
#: (measured: 3e291 rtol from a step whose shifted stage sat where dF/du > 0, the estimate's
#: growth factor exp(h kappa dF/du) overflowing; its ceiling of ACCEPT_STEP then exhausted
#: the step budget); the next round's pass controls the finer steps itself
MAX_REFINEMENT = 4.0

# ---------------------------------------------- the tolerances from rtol (``periodic.tolerances``)
#: tolerance of the loose shooting (step 2)
LOOSE_RTOL = 1e-2
#: the adaptive passes aim at this share of the tolerance (the rest is the margin for the
#: node weights of the converged solution, which the pass only knew approximately)
TARGET_SHARE = 0.8
#: the stage Newton's tolerance is max(STAGE_SHARE rtol, STAGE_FLOOR) times the norm of u
STAGE_SHARE = 1e-5
STAGE_FLOOR = 1e-14
#: the stage tolerance is at most this share of delta_tau (p = 0; ``stage_atol``)
BAND_SHARE = 0.01
#: the shooting's fixed point is within max(SHOOTING_SHARE rtol, SHOOTING_FLOOR) V
SHOOTING_SHARE = 1e-3
SHOOTING_FLOOR = 1e-13
#: U's norm is at least this share of the speed scale V (a body that hardly moves on average)
U_NORM_FLOOR = 1e-3
#: u(0) is bracketed in +-(BRACKET_SPEEDS V + BRACKET_GUESSES |u_guess|)
BRACKET_SPEEDS = 1e3
BRACKET_GUESSES = 10.0

# ----------------------------------- one point's solve (``periodic.point``, ``periodic.shooting``)
#: at most this many loose passes
MAX_LOOSE_PASSES = 8
#: rounds of steps 3-4
MAX_ROUNDS = 4
#: a shooting residual kept where the frozen period map jumps over its fixed point counts
#: this many times its first-order effect on the period integrals (``solve_point``)
RESIDUAL_WEIGHT = 2.0
#: first step of the first pass
FIRST_STEP = 1.0 / 16.0
#: a warm solve stands only where the stage tolerance it used (set by the neighbour's norm and
#: node weights) is at most this factor above the one the point's own converged solution sets
#: (measured without this check: short_period_harmonic point 78 at rtol 1e-3, its neighbour's
#: scaled period 10x longer, 51 steps, estimate 0.84 rtol, error 41 rtol)
WARM_ATOL_SLACK = 2.0
#: frozen-grid Newton passes per round
MAX_FROZEN_PASSES = 30

# --------------------------------------------------------- batches of points (``periodic.driver``)
#: workspace capacity a thread starts with (steps; it doubles when a point needs more)
START_CAPACITY = 512
#: ``in_line``'s relative tolerance on a second difference
IN_LINE_SHARE = 1e-9
#: the fast limit's u (``model.limits.fast_limit_velocity``) that starts the shooting is taken on
#: this many steps: it is a guess (bench, rtol 1e-4: 64 steps cost 18.7 ms per 2,000 points
#: and the loose shooting 605 evaluations per solve, 8 steps 2.8 ms and 604, u = 0 571)
GUESS_STEPS = 8


# ------------------------------------------------------------------ options passed at run time
class ControlOptions(NamedTuple):
    """The step-size controller's settings (``periodic.control.predict_factor``): the factor
    is multiplied by ``safety`` and clipped to [``min_factor``, ``max_factor``]; defaults
    SAFETY, MIN_FACTOR, MAX_FACTOR (documented above)."""

    safety: float = SAFETY
    min_factor: float = MIN_FACTOR
    max_factor: float = MAX_FACTOR


class PointOptions(NamedTuple):
    """One point's solve (``periodic.point``, ``periodic.shooting``): at most
    ``max_loose_passes`` loose passes and ``max_rounds`` rounds, a kept shooting residual
    counted ``residual_weight`` times, the first pass's first step ``first_step``, a warm
    start kept where its stage tolerance is at most ``warm_atol_slack`` times the point's
    own, at most ``max_frozen_passes`` frozen-grid Newton passes per round (also on the
    fixed-grid path, ``periodic.shooting.frozen_orbit``); defaults MAX_LOOSE_PASSES,
    MAX_ROUNDS, RESIDUAL_WEIGHT, FIRST_STEP, WARM_ATOL_SLACK, MAX_FROZEN_PASSES (documented
    above)."""

    max_loose_passes: int = MAX_LOOSE_PASSES
    max_rounds: int = MAX_ROUNDS
    residual_weight: float = RESIDUAL_WEIGHT
    first_step: float = FIRST_STEP
    warm_atol_slack: float = WARM_ATOL_SLACK
    max_frozen_passes: int = MAX_FROZEN_PASSES


class TrapOptions(NamedTuple):
    """The turning-point traps (``periodic.traps``): a step next to a turning point may
    change u by friction at most ``share`` of u, never below ``floor`` at a simple one; a
    converged step over ``slack`` times its ceiling is rejected, its new ceiling at least
    the step over ``span``; defaults TRAP_SHARE, TRAP_FLOOR, TRAP_SLACK, TRAP_SPAN
    (documented above)."""

    share: float = TRAP_SHARE
    floor: float = TRAP_FLOOR
    slack: float = TRAP_SLACK
    span: float = TRAP_SPAN


class StopOptions(NamedTuple):
    """The kinematic stops (``periodic.switching.kinematic_stops``, ``turning_stops``):
    ``samples_per_wavenumber`` samples per wavenumber in the search for zeros, a minimum of
    |omega| below ``tangency_share`` of max |omega| a near-tangency, a turning point simple
    where |omega'| >= ``simple_share`` 2 pi max |omega|, stops closer than ``gap`` one, a
    stop located to ``root_share`` of tau in at most ``root_iterations``; defaults
    SAMPLES_PER_WAVENUMBER, TANGENCY_SHARE, SIMPLE_SHARE, STOP_GAP, KINEMATIC_ROOT_SHARE,
    KINEMATIC_ROOT_ITERATIONS (documented above)."""

    samples_per_wavenumber: int = SAMPLES_PER_WAVENUMBER
    tangency_share: float = TANGENCY_SHARE
    simple_share: float = SIMPLE_SHARE
    gap: float = STOP_GAP
    root_share: float = KINEMATIC_ROOT_SHARE
    root_iterations: int = KINEMATIC_ROOT_ITERATIONS


class EventOptions(NamedTuple):
    """State events (``periodic.events``, the integrator's cuts, ``periodic.estimators``'
    splits): a located event within ``end_share`` of its step of the step's end is on it,
    within ``start_share`` of the previous step of the start not cut; switching functions
    within ``sign_rounding`` of their terms have no sign, nor within ``noise`` stage
    tolerances; a sign change is an event beyond ``crossing_band`` delta_tau; the friction's
    band is ``band`` delta_tau; at most ``max_cuts`` cuts in a row; an event within
    ``split_share`` of a recorded step's end is on it; located to ``root_share`` of the step
    in at most ``root_iterations``.  Defaults EVENT_END_SHARE, EVENT_START_SHARE,
    SIGN_ROUNDING, EVENT_NOISE, CROSSING_BAND, EVENT_BAND, MAX_EVENT_CUTS, SPLIT_SHARE,
    EVENT_ROOT_SHARE, EVENT_ROOT_ITERATIONS (documented above)."""

    end_share: float = EVENT_END_SHARE
    start_share: float = EVENT_START_SHARE
    sign_rounding: float = SIGN_ROUNDING
    noise: float = EVENT_NOISE
    crossing_band: float = CROSSING_BAND
    band: float = EVENT_BAND
    max_cuts: int = MAX_EVENT_CUTS
    split_share: float = SPLIT_SHARE
    root_share: float = EVENT_ROOT_SHARE
    root_iterations: int = EVENT_ROOT_ITERATIONS


class StepOptions(NamedTuple):
    """Step lengths in a pass (``periodic.integrator``, ``periodic.traps``,
    ``periodic.global_error``, ``periodic.point``): below ``min_step`` a pass fails, a step
    of ``accept_step`` or less is accepted whatever its error, a step whose defect model
    does not fit is judged by ``fit_distrust`` times its estimate, a step is stretched to a
    stop within ``stretch`` of it, a pass gives up after ``max_attempts_per_step`` attempts
    per accepted step (+ 16), a refinement ceiling is at most ``max_refinement`` below its
    step; defaults MIN_STEP, ACCEPT_STEP, FIT_DISTRUST, STRETCH, MAX_ATTEMPTS_PER_STEP,
    MAX_REFINEMENT (documented above)."""

    min_step: float = MIN_STEP
    accept_step: float = ACCEPT_STEP
    fit_distrust: float = FIT_DISTRUST
    stretch: float = STRETCH
    max_attempts_per_step: int = MAX_ATTEMPTS_PER_STEP
    max_refinement: float = MAX_REFINEMENT


class StageOptions(NamedTuple):
    """The stage solve (``periodic.radau.radau5_step``): Newton gives up after
    ``max_iterations``; its first correction is taken as the last where the carried
    quadratic constant predicts the next below ``first_correction_share`` of the tolerance,
    and only where dF/du at the predicted stages lies within ``slope_share`` of the previous
    step's end; defaults MAX_STAGE_ITERATIONS, FIRST_CORRECTION_SHARE, SLOPE_SHARE
    (documented above)."""

    max_iterations: int = MAX_STAGE_ITERATIONS
    first_correction_share: float = FIRST_CORRECTION_SHARE
    slope_share: float = SLOPE_SHARE


class DefectOptions(NamedTuple):
    """The defect estimate (``periodic.defect``): its floor is ``noise_gain`` times the
    stages' error; its model fits where the line through the start and the middle sample
    predicts the late one within ``fit`` of it; its resolvent is integrated with the slope
    varying along the step up to |h kappa dF/du| = ``variable_slope_limit``; defaults
    NOISE_GAIN, DEFECT_FIT, VARIABLE_SLOPE_LIMIT (documented above).  (Its two samples are
    the estimator's definition, not options: ``periodic.defect``.)"""

    noise_gain: float = NOISE_GAIN
    fit: float = DEFECT_FIT
    variable_slope_limit: float = VARIABLE_SLOPE_LIMIT


class ToleranceOptions(NamedTuple):
    """The factors by which ``periodic.tolerances`` derives every tolerance from rtol and the
    speed scale V: the loose tolerance max(``loose_rtol``, rtol); the passes' target
    ``target_share`` of their tolerance; the stage tolerance max(``stage_share`` rtol,
    ``stage_floor``) of the norm, for p = 0 at most ``band_share`` delta_tau; the shooting's
    max(``shooting_share`` rtol, ``shooting_floor``) V; U's norm at least ``u_norm_floor`` V;
    u(0)'s bracket +-(``bracket_speeds`` V + ``bracket_guesses`` |u_guess|).  Defaults
    LOOSE_RTOL, TARGET_SHARE, STAGE_SHARE, STAGE_FLOOR, BAND_SHARE, SHOOTING_SHARE,
    SHOOTING_FLOOR, U_NORM_FLOOR, BRACKET_SPEEDS, BRACKET_GUESSES (documented above)."""

    loose_rtol: float = LOOSE_RTOL
    target_share: float = TARGET_SHARE
    stage_share: float = STAGE_SHARE
    stage_floor: float = STAGE_FLOOR
    band_share: float = BAND_SHARE
    shooting_share: float = SHOOTING_SHARE
    shooting_floor: float = SHOOTING_FLOOR
    u_norm_floor: float = U_NORM_FLOOR
    bracket_speeds: float = BRACKET_SPEEDS
    bracket_guesses: float = BRACKET_GUESSES


class BatchOptions(NamedTuple):
    """Batches of points (``periodic.driver``): each thread's step record starts with room
    for ``start_capacity`` steps (it doubles as needed: no result depends on it); a sweep's
    points lie on a line where their second differences are within ``in_line_share``; the
    fast limit's u that starts a cold solve is taken on ``guess_steps`` steps; defaults
    START_CAPACITY, IN_LINE_SHARE, GUESS_STEPS (documented above)."""

    start_capacity: int = START_CAPACITY
    in_line_share: float = IN_LINE_SHARE
    guess_steps: int = GUESS_STEPS


class EngineOptions(NamedTuple):
    """The engine's options passed through its kernels, by role (a numba NamedTuple of
    NamedTuples of floats: every value compiles to one signature).  ``EngineOptions()`` is
    the defaults; ``EngineOptions(control=ControlOptions(max_factor=2.0))`` changes one.
    Checked and normalised by ``checked_options`` before the kernels see it."""

    control: ControlOptions = ControlOptions()
    point: PointOptions = PointOptions()
    traps: TrapOptions = TrapOptions()
    stops: StopOptions = StopOptions()
    events: EventOptions = EventOptions()
    steps: StepOptions = StepOptions()
    stage: StageOptions = StageOptions()
    defect: DefectOptions = DefectOptions()
    tolerances: ToleranceOptions = ToleranceOptions()
    batch: BatchOptions = BatchOptions()


#: the defaults
DEFAULT_OPTIONS = EngineOptions()

#: each option's type and domain: (type, low, high, low included, high included)
_DOMAINS = {
    ("control", "safety"): (float, 0.0, 1.0, False, True),
    ("control", "min_factor"): (float, 0.0, 1.0, False, True),
    ("control", "max_factor"): (float, 1.0, float("inf"), True, False),
    ("point", "max_loose_passes"): (int, 1, 10 ** 6, True, True),
    ("point", "max_rounds"): (int, 1, 10 ** 6, True, True),
    ("point", "residual_weight"): (float, 0.0, float("inf"), True, False),
    ("point", "first_step"): (float, 0.0, 1.0, False, True),
    ("point", "warm_atol_slack"): (float, 1.0, float("inf"), True, False),
    ("point", "max_frozen_passes"): (int, 1, 10 ** 4, True, True),
    ("traps", "share"): (float, 0.0, float("inf"), False, False),
    ("traps", "floor"): (float, 0.0, 1.0, True, True),
    ("traps", "slack"): (float, 1.0, float("inf"), True, False),
    ("traps", "span"): (float, 1.0, float("inf"), True, False),
    ("stops", "samples_per_wavenumber"): (int, 4, 10 ** 5, True, True),
    ("stops", "tangency_share"): (float, 0.0, 1.0, True, True),
    ("stops", "simple_share"): (float, 0.0, float("inf"), True, False),
    ("stops", "gap"): (float, 0.0, 1e-3, True, True),
    ("stops", "root_share"): (float, 0.0, 1e-3, False, True),
    ("stops", "root_iterations"): (int, 1, 10 ** 4, True, True),
    ("events", "end_share"): (float, 0.0, 0.5, True, False),
    ("events", "start_share"): (float, 0.0, 0.5, True, False),
    ("events", "sign_rounding"): (float, 0.0, 1e-3, True, True),
    ("events", "noise"): (float, 0.0, float("inf"), True, False),
    ("events", "crossing_band"): (float, 0.0, float("inf"), True, False),
    ("events", "band"): (float, 0.0, float("inf"), True, False),
    ("events", "max_cuts"): (int, 0, 10 ** 4, True, True),
    ("events", "split_share"): (float, 0.0, 0.5, True, False),
    ("events", "root_share"): (float, 0.0, 1e-3, False, True),
    ("events", "root_iterations"): (int, 1, 10 ** 4, True, True),
    ("steps", "min_step"): (float, 0.0, 1e-3, False, True),
    ("steps", "accept_step"): (float, 0.0, 1e-3, False, True),
    ("steps", "fit_distrust"): (float, 1.0, float("inf"), True, False),
    ("steps", "stretch"): (float, 1.0, 2.0, True, True),
    ("steps", "max_attempts_per_step"): (int, 1, 10 ** 6, True, True),
    ("steps", "max_refinement"): (float, 1.0, float("inf"), False, False),
    ("stage", "max_iterations"): (int, 1, 10 ** 4, True, True),
    # (above 1 the first correction would be kept where the next is predicted above atol)
    ("stage", "first_correction_share"): (float, 0.0, 1.0, True, True),
    ("stage", "slope_share"): (float, 0.0, float("inf"), True, False),
    ("defect", "noise_gain"): (float, 0.0, float("inf"), True, False),
    ("defect", "fit"): (float, 0.0, float("inf"), True, False),
    # (beyond 32 the 8-point rule misses the resolvent's integral by more than 2 %:
    # 2.4e-2 at z = -32, 0.26 at -64, against 2.5e-4 at -16)
    ("defect", "variable_slope_limit"): (float, 0.0, 32.0, True, True),
    ("tolerances", "loose_rtol"): (float, 0.0, 1.0, False, False),
    ("tolerances", "target_share"): (float, 0.0, 1.0, False, True),
    ("tolerances", "stage_share"): (float, 0.0, 1.0, False, True),
    ("tolerances", "stage_floor"): (float, 0.0, 1e-3, True, True),
    ("tolerances", "band_share"): (float, 0.0, 1.0, False, True),
    ("tolerances", "shooting_share"): (float, 0.0, 1.0, False, True),
    ("tolerances", "shooting_floor"): (float, 0.0, 1e-3, True, True),
    ("tolerances", "u_norm_floor"): (float, 0.0, 1.0, False, True),
    ("tolerances", "bracket_speeds"): (float, 0.0, float("inf"), False, False),
    ("tolerances", "bracket_guesses"): (float, 0.0, float("inf"), True, False),
    ("batch", "start_capacity"): (int, 1, 2 ** 24, True, True),
    ("batch", "in_line_share"): (float, 0.0, 1.0, True, False),
    # (``model.kinematics.period_grid`` gives each of two phases at least 2 steps)
    ("batch", "guess_steps"): (int, 4, 2 ** 16, True, True),
}


def checked_options(options) -> EngineOptions:
    """``options`` (an EngineOptions, or None for the defaults) with every field of its
    type (float or int) and in its domain, so that the kernels compile once for every value
    (an int where a float belongs would be another numba type, another compile).  Raises
    ValueError naming the option."""
    if options is None:
        return DEFAULT_OPTIONS
    if not isinstance(options, EngineOptions):
        raise ValueError(f"options: expected an EngineOptions, got {type(options).__name__}")
    roles = {}
    for role, group in zip(EngineOptions._fields, options):
        default = getattr(DEFAULT_OPTIONS, role)
        if not isinstance(group, type(default)):
            raise ValueError(f"options.{role}: expected a {type(default).__name__}, "
                             f"got {type(group).__name__}")
        values = {}
        for name, value in zip(group._fields, group):
            kind, lo, hi, lo_in, hi_in = _DOMAINS[(role, name)]
            try:
                x = float(value)
                if kind is int:
                    if isinstance(value, bool) or x != int(x):
                        raise ValueError
                    x = int(x)
            except (TypeError, ValueError, OverflowError):
                what = "an integer" if kind is int else "a number"
                raise ValueError(f"options.{role}.{name}: expected {what}, got {value!r}") from None
            if not ((lo < x or (lo_in and x == lo)) and (x < hi or (hi_in and x == hi))):
                span = f"{'[' if lo_in else '('}{lo:g}, {hi:g}{']' if hi_in else ')'}"
                raise ValueError(f"options.{role}.{name}: must lie in {span}, got {value!r}")
            values[name] = x
        roles[role] = type(default)(**values)
    return EngineOptions(**roles)
