"""Every tunable of the diagnosis in one place, each with the reason for its value.

:class:`DiagnosisConfig` is passed to :func:`ident.diagnosis.diagnose` (``config=``); the
module-level :data:`DEFAULT` is what the CLI and the Python API use.  Nothing here was
fitted to a benchmark case: the acceptance figures are statistical conventions or the
resolution a CNC axis measures with; the search figures trade time against the chance of
missing a valley and are the same for every effect.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["DiagnosisConfig", "DEFAULT"]


@dataclass(frozen=True)
class DiagnosisConfig:
    # -- acceptance (diagnose.evidence) ------------------------------------------------
    #: Significance of the held-out likelihood-ratio test: a 5 % family-wise error,
    #: Bonferroni-divided over the six effects tried.
    alpha: float = 0.05 / 6
    #: An effect must also remove this share of the held-out residual norm: below it an
    #: effect is statistically real but too small to matter for a virtual machine.
    min_relevant: float = 0.03
    #: An effect's model contains the reference (effect off), so it must fit the training
    #: data at least as well; one that fits them worse sits in another valley of the base
    #: parameters and its held-out gain is that valley's, not the effect's.
    nested_training: bool = True
    #: The held-out residuals are coloured; besides the slow noise model (N/τ effective
    #: samples, τ the residual's correlation time: it counts a sharp effect, a gap's steps
    #: at reversals, as if it were as slow as the base's residual) the likelihood ratio is
    #: also taken on both residuals whitened by the prediction-error filter of an AR model
    #: of the augmented model's residual, order ≤ this (least BIC).  10 samples span the
    #: loop's fast dynamics at 1 kHz; on the one case looked at BIC chose the same order
    #: with 30 allowed.  0: the slow noise model alone.
    ar_order_max: int = 10
    #: Of the effects that pass, the first named is the one removing the largest share of
    #: the held-out residual: the evidence says an effect is real, its size which matters
    #: most.  (False: the strongest evidence, −log10 p, first — with the whitened statistic
    #: that ranks a fast effect explaining less above a slow one explaining more.)
    rank_by_gain: bool = True
    #: A described external load must remove this share of the residual norm …
    min_gain: float = 0.04
    #: … plus this much per parameter it adds (2 per time block).
    per_param: float = 0.01
    #: An effect must explain more than this many times the measurement noise rms
    #: (√(rms_before² − rms_after²) of the held-out residual, diagnose._above_noise): less
    #: changes the prediction by less than the sensor scatters (SPEC §7 "none").  It is the
    #: part an effect removes that must exceed the noise, not the whole residual: a rule on the
    #: whole residual vetoes any gain (drive-zoo-dev case_007's cyclic error, 65 % of a 1.35 µm
    #: residual at 0.48 µm noise, −log10 p 3152, was called none by it).
    noise_factor: float = 1.0

    # -- what each effect's name means (Effect.implausible) and the fits' boxes ----------
    #: A backlash gap below this (mm) is below the 1 µm resolution CNC scales and encoders
    #: measure with: not a gap the data can show.
    min_gap_mm: float = 0.001
    #: A breakaway force within this ratio of Coulomb friction is no Stribeck effect at the
    #: scale eq. 3.2 resolves.
    min_static_ratio: float = 1.2
    #: A resonance is fitted as a lightly damped mode: ζ at most this.  A fit held on it is
    #: a better-damped pole pair the data want — a filter eq. 3.3's continuous loop lacks
    #: against a digital controller — and is not named a resonance (what the name means,
    #: effects.Resonance.implausible); a fit on the lower bound is a mode whose damping is
    #: not resolved, and is told so.
    max_mode_damping: float = 0.15
    #: A position-periodic error must show at least this many whole periods over the travel
    #: recorded: less than one is a position map the data cannot tell from a slow drift.
    min_periods: float = 1.0
    #: Lowest frequency a mode is started at, Hz (below, the loop itself and the moves dominate).
    min_mode_hz: float = 5.0
    #: Starts of a mode on a log grid from 10 Hz to 0.3/Ts, this many points (besides the
    #: residual spectrum peaks); 8 changed nothing on the tuning seeds' cases where the mode
    #: was missed — the screen had dropped the right start, not the grid missed it.
    mode_grid_points: int = 4
    #: Residual spectrum peaks holding at least this share of the residual power start a mode.
    peak_min_share: float = 0.15
    #: A mode started at such a peak is fitted inside this band (× the peak frequency): a
    #: two-mass mode shows between f·√μ and f in closed loop, so its free-free frequency
    #: lies at or above the peak.
    peak_band: tuple[float, float] = (0.9, 1.4)
    #: Start two-mass modes of a semi-closed loop whose recorded position is the motor
    #: encoder (resonance mode 3: the mode shows only through the table's reaction).
    motor_recorded_mode: bool = True
    #: A fitted two-mass mode is scanned along its ridge of equal locked-motor frequency
    #: (candidates.scan_motor_fraction) at these motor shares, spread over the bound of
    #: ``motor_fraction`` (0.2–0.98) …
    mode_share_grid: tuple[float, ...] = (0.25, 0.4, 0.55, 0.7, 0.85)
    #: … each point fitted for this many iterations on the race's windows.
    mode_scan_iter: int = 8

    # -- search (candidates.search) ----------------------------------------------------
    #: Recordings longer than this (s) are scored on one hold-out fold instead of two and
    #: get one second effect tried instead of two (time budget).
    long_s: float = 10.0
    #: Of all starts of an effect, at most this many (lowest free-run cost with the base
    #: held; the best of every variant always) enter the race below.  Generous on
    #: purpose: with the base held a large gap or a low mode costs more than a small one
    #: even where it is the truth, so a tight screen would rank away the right start (a
    #: two-mass mode's valley is narrow in frequency and motor share: with 16, a 45 Hz PID
    #: mode's start was screened out and a 5 ms delay named instead; with 24, independent
    #: bench tuning seed 1044.2's 37 Hz PID mode) …
    screened_starts: int = 32
    #: The race of the surviving starts (successive halving over the share of the
    #: recording fitted, a multi-fidelity race): round i fits every start still in the race
    #: jointly for ``race_iter[i]`` iterations on the first ``race_fidelity[i]`` of every
    #: segment, then the better half by training cost goes on.  Early rounds on part of
    #: the recording are cheap, so every start gets enough iterations for the base to move
    #: back from the valley where it absorbed the effect before starts are compared (after
    #: two iterations a large gap still costs more than a small one even where it is the
    #: truth: LinuxCNC 20 µm gap); a quarter of each segment still holds dozens of moves.
    #: The last round ranks the best start of each variant against the others, and a
    #: variant's valley shows only once the base has moved into it: with 4 iterations there
    #: a wound-up integral lost to the frozen one (tests/test_diagnosis_saturation.py), though
    #: the tuning sets named as many.
    race_fidelity: tuple[float, ...] = (0.25, 0.5, 1.0)
    race_iter: tuple[int, ...] = (8, 8, 8)
    #: When > 0: "the whole" is at most this many seconds of the recording, in windows
    #: spread over all of it (:meth:`~ident.diagnosis.spec.Chunk.windows`: each restarts
    #: mid-move on the recorded state, a short lead-in unscored), and only the winner's
    #: polish sees every sample, so a long recording costs the race no more than one of
    #: this length.  A ranking needs a number of moves, not a share of a recording.  6 s:
    #: on the independent bench's tuning seeds 52/69 against 51/69 (0/10 false alarms
    #: both) at a median diagnosis of 11.5 s against 25.4 s; drive-zoo-dev 16/21 as
    #: without it.  4 s lost gaps: tuning seeds' backlash 5 → 3/10 (52/69
    #: overall, as with 6 s), report seeds' 5 → 2/10, for a median diagnosis 17 % shorter.
    #: (The first 10 s of every segment instead lost two zoo cases: on a
    #: one-segment recording the early rounds saw only its beginning.)  A
    #: recording shorter than twice this is raced as when 0: windows would save little
    #: there and add restarts (a 6.8 s LinuxCNC capture lost its 20 µm gap to them).
    race_seconds: float = 6.0
    #: Windows of about this many seconds each (see :meth:`~ident.diagnosis.spec.Chunk.windows`) …
    race_window_s: float = 1.0
    #: … each restarting mid-move between this long and twice this long before its first
    #: scored sample (where the recorded position is closest to a parabola: its velocity
    #: and acceleration read best); the restart's error decays in the unscored lead-in.
    race_lead_s: float = 0.1
    #: When given, the race's fits in round i are secant Levenberg–Marquardt
    #: (:func:`ident.least_squares.secant_lm`) with ``race_evals[i]`` simulations per start
    #: (0: differences as above, n + 1 simulations an iteration).  Off: on the tuning
    #: seeds (36, 36, 36) cut the diagnosis median from 24.8 to 15.4 s but named 42/69
    #: against 44/69 — resonance 2/10 against 6/10 (a mode's valley is narrow in frequency
    #: and a secant Jacobian steps over it), saturation 7/9 against 4/9 — and (36, 36, 0)
    #: lost the same modes (first 59 cases: 35 against 39 for both).  Milder, the race's
    #: differences taken every other iteration only, Broyden's update carrying the
    #: Jacobian in between, on every trial point: 0.85x the CPU of the timing cases
    #: (bench_diagnosis_speed.py --compare) but drive-zoo-dev + dev2 44/49 against 47/49
    #: (a gap taken for a gap and a mode; a dead time, a gap and a mode missed).
    race_evals: tuple[int, ...] = ()
    #: … down to at least this many starts (the best of every variant always stays) …
    joint_starts: int = 2
    #: … then the winner is polished on the whole chunk: half this many iterations with the
    #: coarse difference step, then a quarter with the fine one.
    joint_iter: int = 20
    #: Multiple shooting (candidates.shoot): when > 0, the race's winner is fitted on every
    #: scored sample cut into windows of about this many seconds, each simulated from the
    #: recorded state (:meth:`~ident.diagnosis.spec.Chunk.shots`), before its polish in
    #: free run.  Over a long free run a lightly damped mode or stick-slip drifts in phase
    #: and the simulation-error cost ripples (Ribeiro et al., Automatica 2020): a mode's
    #: fit escapes to high damping, a friction fit to another valley.  Over a window a few
    #: periods of the slowest mode long (0.1–0.5 s) the error cannot drift far and the
    #: cost is smooth.  Each window's initial state is estimated (spec.estimated_states).
    #: 0: off (the polish starts from the race's winner).  Off because it names nothing
    #: more: with 0.3 s, drive-zoo-dev2 20/28 as without it (the same hits, main
    #: parameters within 3 points; the 73 Hz mode case → none instead of → time_delay),
    #: drive-zoo-dev 20/21 against 21/21 (a dead time gets a resonance beside it), at 1.30×
    #: the CPU (bench_diagnosis_speed.py --compare).  The misses it was meant for are no
    #: ripple: over the windows a lightly damped mode still costs 2–4× the fit on the
    #: damping bound (bench_shooting_profile.py); a missed Stribeck curve predicts the
    #: held-out windows better (case_006: 5 %) but drifts in free run, which judges.
    shooting_window_s: float = 0.0
    #: Judge on held-out windows (diagnose.evidence and every held-out condition of the
    #: acceptance): when True the held-out residuals the acceptance rule reads are those of
    #: the windows of ``shooting_window_s`` (k-step-ahead, each window simulated from the
    #: recorded state, its restart state estimated — the same three nuisance states for the
    #: reference and the candidate, so the degrees of freedom stay the effect's added
    #: parameters); the free-run figures are told beside them.  Needs ``shooting_window_s``
    #: > 0.  False: the free run judges, the windows figure is told beside it.  Off because
    #: it names no more (bench_drive_zoo.py --config '{"shooting_window_s": 0.3,
    #: "accept_on_windows": true}'): drive-zoo-dev 21/21 as main (case_014's delay without
    #: the resonance shooting alone adds beside it), drive-zoo-dev2 20/28 as main but not
    #: the same: case_014's saturation named resonance (a 14.7 Hz mode on the recorded
    #: position, 7 % of the held-out windows' residual, −0.5 % in free run) where the free
    #: run named nothing, case_015's mode none where the free run named a dead time; false alarms on clean cases
    #: 0/7.  On the windows eight candidates of a wrong effect pass alone that the free run
    #: refuses.  1.28× the CPU of the default (bench_diagnosis_speed.py --compare, shooting
    #: included).
    accept_on_windows: bool = False
    #: Judge the held-out data also restarted at rest (diagnose.evidence; spec.rest_residual):
    #: the simulation restarted at the recorded position at the end of every dwell of the
    #: command, the force friction holds there profiled out (a stuck axis shows where it
    #: stands, not that force).  A stick-slip model follows the recording in free run only as
    #: long as every marginal breakaway comes at the same instant: drive-zoo-dev2 case_006's
    #: Stribeck fit removes 36 % of the training residual and −2 % of the held-out one in
    #: free run, and moving its breakaway ratio by 0.3–1 % moves the held-out figure between
    #: −14 % and +3 %, restarted at rest 70–73 % (benchmarks/bench_stick_slip.py): one missed
    #: breakaway leaves the axis stuck at another place until the next move.  An effect of
    #: ``rest_effects`` passes when the rule holds on the free run or on the restarted
    #: reading, each at half the level (Bonferroni: two readings of the same held-out data);
    #: the other reading's figures stay beside it.  False: the free run alone.
    accept_on_rests: bool = True
    #: … for these effects: a friction whose breakaway exceeds its Coulomb level makes an
    #: axis under integral action hunt (stick, wind up, break away, overshoot, stick again;
    #: Olsson & Åström, "Friction generated limit cycles", IEEE TCST 2001: with Coulomb
    #: friction alone it does not), and that limit cycle's breakaways are marginal in time.
    #: A restart at rest also forgets what a rest does not show of other effects — which
    #: side of a gap the motor rests on, a delay's history — and their fits then take up
    #: the profiled force's misreads: on the development zoos a gap passed alone restarted
    #: at rest on two time-delay and Stribeck cases (9–11 %), and a dead time beside a gap
    #: (4 %) became a second effect; judged on the free run alone they pass nowhere.  So
    #: the restarted reading is taken only while every effect of both models compared is one
    #: of these (diagnose._readings): beside a gap a Stribeck curve took up the gap model's
    #: misread (drive-zoo-dev case_001 named backlash + stribeck).
    rest_effects: tuple[str, ...] = ("stribeck",)
    #: … a dwell of the command at least this long ends in a restart (s): longer than a
    #: move's settling on the loops CNC drives have (bandwidth ≥ 20 Hz: 8 ms time constants) …
    rest_restart_s: float = 0.05
    #: … and the force held at each restart is profiled over this many values spread evenly
    #: over this multiple of the model's stick band [r·d1, r·d0]: the output a sampled loop
    #: holds over a sample can exceed the breakaway level while its axis slips by less than
    #: the encoder resolves and sticks again.  On the regenerable stick-slip fixture of
    #: tests/test_diagnosis_rests.py (a clean drive with Coulomb friction: the true model's
    #: restarted residual 88 → 12 against 1.9 in free run, wrong Stribeck curves 210–300
    #: either way) the band itself misread it; 1.5 and 2 gave the same.
    rest_force_span: float = 1.5
    rest_force_grid: int = 31
    #: … each window restarting between this long and twice this long before its first
    #: scored sample (the lead-in, unscored, where a delay's history and what the estimated
    #: states leave — the side of a gap, stick or slip — settle) …
    shooting_lead_s: float = 0.1
    #: … fitted for this many iterations (coarse difference step) before the polish.
    shooting_iter: int = 10
    #: Forward-difference steps of the fits in scaled units (relative to the start): the
    #: coarse one reads the slope through a ripple of the cost, the fine one polishes.
    fd_step: float = 1e-3
    fd_step_rough: float = 1e-2
    #: Exact Jacobians (complex-step sensitivities of the simulation,
    #: :func:`ident.diagnosis.spec.residual_jacobian`) in place of the fine differences
    #: (``exact_fine``) and of the coarse ones (``exact_rough``), on every model (the
    #: saturation's freeze off the exact step is continuous, ident.kernel._integral_share).
    #: The intervals' Jacobian is exact either way.  Off: on the tuning sets, one run each,
    #: differences → exact fine and coarse with ``fit_log``: drive-zoo-dev + drive-zoo-dev2
    #: 47/49 → 44/49 (resonance 5/7: a mode lost to a gap or a dead time by a hair's
    #: breadth of held-out residual, a mode added beside a gap or a dead time), also with
    #: the race's Jacobian carried over every other step by Broyden's update (20/21 +
    #: 24/28); the diagnosis 1.39× as long (bench_diagnosis_speed.py --compare: a
    #: complex-step column costs 2.2–2.6 real runs); from a full-closed gap started 30 %
    #: long the re-estimation stops at a kink of the hunting's cost at 7× the cost the
    #: differences reach (tests/test_diagnosis_units.py's stationary-point fixture).
    exact_fine: bool = False
    exact_rough: bool = False
    #: Fit an effect's parameters whose box lies above zero (a frequency, a damping, a gap,
    #: a dead time, a limit, a Stribeck velocity) by their logarithm: a step changes them by
    #: a factor.  In linear coordinates the first Gauss–Newton step of an exact Jacobian
    #: leaps to the floor of a box, where the effect vanishes and the cost is flat, and stops
    #: there (tests/test_diagnosis_shooting.py's Stribeck start: v_s to 1e-4 mm/s);
    #: drive-zoo-dev2 with exact Jacobians, one run each: 24/28 in linear coordinates (a
    #: Stribeck velocity on its floor in case_015), 25/28 in log coordinates.  Goes with
    #: the exact Jacobians; off with them.
    fit_log: bool = False
    #: Fit β = b2 − a2 in place of b2 (eq. 3.3's position gains): b2·x_r − a2·x becomes
    #: a2·(x_r − x) + β·x_r, so a step on a2 moves u by a2's share of the tracking error,
    #: not of the position (~100 mm): b2 and a2 nearly cancel and a fit on them crawls
    #: (the base re-fit reaches its minimum in 15 iterations instead of 60).
    #: "all": every fit; "searches": the race and polish of an effect's search only, the
    #: base, reference and final re-fits keeping b2; "none": b2 everywhere.  One
    #: run each (tuning seeds / drive-zoo-dev / battery, with the noise rule above): none
    #: 52/17/62 (without it), all 54/20/62, searches 56/20/63 — within the rounding band
    #: of each other; "all" is one parametrisation for every fit and takes the 25 s timing
    #: case 4.8-4.9 s against 5.4 s.  β's scale is at least
    #: 1e-4·a2, the floor of the friction terms: β multiplies x_r as they multiply 1.
    fit_beta: str = "all"
    #: Base re-fit iterations of the reference models (re-fits from every candidate's base).
    reference_iter: int = 15

    # -- the accepted model's parameters (candidates.segment_variance_fit) --------------
    #: The accepted model is re-fitted with a noise variance of each segment's own
    #: (iteratively reweighted least squares): at most this many re-weightings (0: off) …
    segment_variance_steps: int = 5
    #: … each followed by this many iterations …
    segment_variance_iter: int = 10
    #: … until no segment's weight moves by more than this share.
    segment_variance_tol: float = 0.05
    #: An accepted gap is then profiled (candidates.profile_gap): the model re-fitted with
    #: the gap held at these multiples of the fitted one (0: none) …
    gap_profile_ratios: tuple[float, ...] = (0.7, 1.3, 1.7)
    #: … for this many iterations each.
    gap_profile_iter: int = 10
    #: The accepted model, re-weighted and profiled, is last polished with exact Jacobians
    #: (``exact_fine``, ``exact_rough`` and ``fit_log`` on) for ``segment_variance_iter``
    #: iterations: the search chose the valley with its difference steps, the estimate is
    #: the valley's floor.  On the tuning sets, one run each: every verdict as without it,
    #: zoo main parameters within 25 % 23/26 → 24/26.
    estimate_exact: bool = True

    # -- a weakly determined dead time (candidates.centre_delay) ------------------------
    #: Delays whose training cost lies within this share of the best fit equally well (2 %
    #: of the cost is 1 % of the residual norm, a third of ``min_relevant``) …
    delay_profile_tol: float = 0.02
    #: … searched for between these multiples of the fitted delay …
    delay_scan_range: tuple[float, float] = (0.1, 3.0)
    #: … with a first step of this share either way, then this many halvings …
    delay_scan_step: float = 0.1
    delay_bisections: int = 4
    #: … each point a base re-fit of this many iterations.
    delay_profile_iter: int = 8
    #: … or, when > 0, a secant re-fit with this many simulations (see ``race_evals``;
    #: measured only together with it).
    delay_profile_evals: int = 0

    def __post_init__(self) -> None:
        if self.fit_beta not in ("searches", "all", "none"):
            raise ValueError(f"fit_beta must be 'searches', 'all' or 'none', not {self.fit_beta!r}")
        if self.accept_on_windows and not self.shooting_window_s > 0:
            raise ValueError("accept_on_windows needs shooting_window_s > 0 (the windows' length)")


DEFAULT = DiagnosisConfig()
