//! The diagnosis's tuning in one place: how many candidates each stage looks at, how many
//! iterations its fits get, and the levels its decisions use, each with the reason for its value
//! (the statistics, or what was measured on the blind suite). The stages are those of the crate's
//! module doc; `docs/diagnosis.md` gives their statistics and measured performance.

use crate::EQUIVALENT_LR;

// The base fit the diagnosis starts from (`base.rs`).

/// Continuations of the base fit from its own best point before extra starts are tried.
pub(crate) const BASE_CONTINUATIONS: usize = 3;

/// Starts of the multi-start base fit (the identification's starting point and points spread
/// over the bounds) when the continued fit does not converge or does not explain the data.
pub(crate) const BASE_STARTS: usize = 4;

// Ranking (`round.rs`, `score.rs`).

/// Candidates whose projected directions agree to this |cos| form one family in the ranking.
pub(crate) const EQUIVALENT_COS: f64 = 0.99;

/// Tuning frequencies tried per resonance width (`ψ/2π` in log-frequency) in a resonator's cell.
pub(crate) const TUNING_STEPS_PER_WIDTH: f64 = 2.0;

// The screen (`screen.rs`, `round::screen_leading`).

/// Candidates passing the score's gate that are screened by a finite step, best score first.
pub(crate) const SCREENED: usize = 30;

/// Of every kind, its best-scored candidates screened besides the [`SCREENED`] leaders: the score
/// is a slope at the nested value and can rank a kind's large effect below another kind's
/// small ones; each kind gets a finite-step look.
pub(crate) const SCREENED_PER_KIND: usize = 2;

/// The screen evaluates a candidate as a low-rank update of the current fit's solves only on
/// models of more DOFs than this. Below it the full solve (a dense LU per line of a matrix this
/// small) costs no more than reading the update's support off the base: one screen evaluation
/// took 0.5-1.1× the full solve's time at 24-78 DOFs and 5.7-12× less at 150-216
/// (`docs/diagnosis.md`, Scaling). The answers are the same either way (to 1e-9).
pub(crate) const LOW_RANK_MIN_DOFS: usize = 100;

/// Iterations of the screen's minimization over a candidate's own parameters.
pub(crate) const SCREEN_ITERATIONS: usize = 5;

/// Tuning frequencies of a resonator's starting grid across its range.
pub(crate) const RESONATOR_GRID: usize = 24;

/// A refit starts where the new parameters are this fraction of the way from their nested values
/// to the given start, whichever fits best.
pub(crate) const REFIT_START_FRACTIONS: [f64; 4] = [1.0, 0.3, 0.1, 0.03];

/// And where the effect's size is its nested value ± its scale times ten to these powers.
pub(crate) const REFIT_SIZE_DECADES: [i32; 6] = [-2, -1, 0, 1, 2, 3];

/// And, where the nested value is itself a size (a split joint group's ψ, a body's mass), at
/// these multiples of it: ψ divides the resonance peaks, and a joint's own ψ can be a fraction
/// or a multiple of its group's, far from any step of the group's size (a split ψ at a quarter
/// of its group's, refitted from the additive steps, stops half-way and is not added; these
/// starts reach it, and a split ψ five times its group's).
pub(crate) const REFIT_SIZE_FACTORS: [f64; 7] = [0.03, 0.1, 0.2, 0.3, 0.5, 2.0, 3.0];

// Refits of the leading families and their escalation (`round::refit_leading`).

/// The distinct (not mirror-image) members of a family that are refitted. The score test cannot
/// tell a family's members apart, but a finite effect can: the true placement of a large spring
/// ends at the noise level while its look-alikes end hundreds of times above it.
pub(crate) const MEMBERS_REFITTED: usize = 4;

/// The score's leading families refitted whatever their screens (see [`refit_jobs`]).
pub(crate) const SCORE_FAMILIES_REFITTED: usize = 2;

/// A misfit above this reduced χ² is large: refits then explore their starts.
pub(crate) const LARGE_MISFIT: f64 = 2.0;

/// Pseudo-residuals a characteristic needs for its data-implied noise level (`noise.rs`), the
/// level "large" is judged against when the noise is known only up to scale: the median of 20
/// values estimates a spread to about ±30 % (its standard error is 1.25/√n of it for Gaussian
/// values), enough to tell a misfit tens of times the noise from one at it.
pub(crate) const NOISE_MIN_PSEUDO_RESIDUALS: usize = 20;

/// With R known only up to scale, the RMS misfit a model of the right form leaves on real data,
/// in units of the data's own noise (`noise.rs`): the level "large" ([`LARGE_MISFIT`] times it)
/// and "above the noise" are judged against. Measurement noise is not what bounds a real
/// structure's fit: the sensors' and the force gauge's masses, modes outside the model and
/// nonlinearity keep a model of the right form tens of times above it, and judged against the
/// noise alone every misfit counts as large and every round runs the batches meant for a large
/// missing effect (on the three-storey example: 3× the CPU time for the same answer).
/// Measured on that set (`docs/real-structure.md`, §8): noise 1.25 % (0.11 dB) in log-amplitude;
/// the right form's fit 28× it (3.09 dB, reduced χ² 0.4 against this floor: not large, not
/// above it); a storey held 10× too stiff 93× (10.1 dB, reduced χ² 4.3: large). The first would
/// count as above the floor below a factor of 28, the second would stop counting as large above
/// 66; 45 lies near their geometric middle (43). Calibrated on that one real set.
pub(crate) const REAL_FLOOR_OVER_NOISE: f64 = 45.0;

/// Candidates of each kind given a short refit (see [`short_refits`]): as many distinct scores.
pub(crate) const SHORT_REFITS_PER_KIND: usize = 12;

/// Candidates of each kind given a short refit although their score rules them out (see
/// [`pulled_against`]).
pub(crate) const PULLED_PER_KIND: usize = 3;

/// Iterations of a short refit.
pub(crate) const SHORT_REFIT_ITERATIONS: usize = 40;

/// The iterations (in all) after which a round's short refits from the current fit are ranked
/// and only the lowest share runs on (successive halving, `round::halve`); the last is
/// [`SHORT_REFIT_ITERATIONS`]. Of a 28-body machine's 700 candidates, the eight that ended lowest
/// after 40 iterations were all within the lowest 31 after 4.
pub(crate) const SHORT_REFIT_RUNGS: [usize; 3] = [4, 12, SHORT_REFIT_ITERATIONS];

/// The rungs of the short refits from the variables' initial values: these start at the
/// variables' own misfit, far above, and their order after 4 iterations tells nothing (the two
/// that ended lowest of 704 ranked 593rd and 644th there); after 8 they were within the lowest 8.
pub(crate) const FRESH_REFIT_RUNGS: [usize; 3] = [8, 20, SHORT_REFIT_ITERATIONS];

/// The share of the short refits still running that goes on to the next rung.
pub(crate) const SHORT_REFIT_KEPT: f64 = 1.0 / 4.0;

/// Short refits (of each start) that all run to the end, whatever their order on the way: the
/// halving only thins beyond them. Near the noise level the order after a few iterations is a
/// poor guide (on FWD-32J's blind cases, with 130-145 candidates, the one that ended lowest was
/// 70th after 4 iterations, and a cut at 48 lost the lowest end in three of seven stages); the
/// hundreds of a large model are mostly hopeless and thin safely.
pub(crate) const SHORT_REFIT_MIN_KEPT: usize = 160;

/// Steps per decade of the size grid of [`fresh_start`].
pub(crate) const FRESH_SIZES_PER_DECADE: i32 = 4;

/// Decades of an effect's scale the size grid of [`fresh_start`] spans on either side of its
/// nested value: wider than the refit's starts ([`screen::REFIT_SIZE_DECADES`]), as the grid
/// costs one evaluation a size and a scale is only a guess (a flexibility's is the stiffest
/// joint's compliance, about 1e-13 m/N on FWD-32J, and a missing flexibility of a column or an
/// overarm lies near 1e-9 m/N, four decades above it).
pub(crate) const FRESH_SIZE_DECADES: std::ops::RangeInclusive<i32> = -2..=6;

// Acceptance (`round.rs`).

/// Least share of the misfit above the noise level an effect must explain to be added.
pub(crate) const MIN_EXCESS_SHARE: f64 = 0.1;

/// Of each kind of effect, the best-scored candidates screened besides the leading
/// [`SCREENED`] (candidates with equal scores, e.g. the moment stiffnesses of the isolators
/// under one body, count once). A large missing effect of one kind can score below tens of
/// another's that fit part of it (an isolator's missing moment stiffness can score below dozens
/// of resonators and springs that each mimic part of it, and still refit to the noise level).
/// The significance level at which a swap's alternative (`swap.rs`)'s size must stand from its nested value (its
/// 95 % interval excludes it). Not the round's (Bonferroni over a thousand candidates): the
/// alternative replaces an effect already significant at that level, and what the swap decides
/// is which of the two forms the data prefer. The Cramér-Rao interval of a stiffness is a poor
/// guide to a large one: an SDE's missing moment stiffness can stand only about 4 standard
/// errors from zero where its LR against the fit without it is above 100 (the likelihood is far
/// from quadratic in a large stiffness).
pub(crate) const SWAP_LEVEL: f64 = 0.05;

// After acceptance: placement, relocation (`placement.rs`).

/// Places whose short refit ends below the effect's own place's are refitted in full, at most
/// this many, lowest first (see [`relocate`]).
pub(crate) const RELOCATIONS_REFITTED: usize = 3;

/// Iterations of a relocation's short refit at each place, for a point mass or resonator.
pub(crate) const RELOCATION_ITERATIONS: usize = 10;

/// Iterations of a relocation's short refit at each place, for a spring: a spring moved to
/// another pair of bodies is a new load path, and the model's variables take longer to follow
/// it than a mass moved to another point: measured on the blind suite, after 10 iterations a
/// spring's true place can rank below several wrong ones (so the few refitted in full miss it),
/// after 30 it ranks first.
pub(crate) const SPRING_RELOCATION_ITERATIONS: usize = 30;

/// Least share of the misfit above the noise level that an effect must remove to be moved.
pub(crate) const RELOCATION_MIN_SHARE: f64 = 0.5;

// Swaps (`swap.rs`).

/// Iterations of an alternative's short refit. It starts from the model's variables at their
/// initial values (see [`fresh_start`]): the fit without the accepted effect has bent them to
/// mimic it. Measured on the blind suite where an SDE's missing stiffness was taken for a spring:
/// after 10 iterations the true alternative is not always among the first few, after 20 it is
/// first and at its full refit's criterion; from the fit without the effect instead, even 40
/// iterations do not always find it.
pub(crate) const SWAP_ITERATIONS: usize = 20;

/// Alternatives whose short refit ends below the accepted fit, or less than
/// [`LOOK_ALIKE_WINDOW`] above it, are refitted in full, at most this many, lowest first.
pub(crate) const SWAPS_REFITTED: usize = 3;

/// How far above the accepted fit (in likelihood ratio) an alternative's short refit may end and
/// still be refitted in full: a short refit stops before its end, and the full one may end where
/// the data cannot tell it from the accepted effect: an SDE's missing stiffness accepted as a
/// spring between the same two bodies at the noise level, whose own form (one parameter fewer)
/// refits to a criterion a few units above the answer's, is within the margin and is listed
/// beside the spring.
pub(crate) const LOOK_ALIKE_WINDOW: f64 = 2.0 * EQUIVALENT_LR;

// The pair judgement (`pairs.rs`).

/// First effects judged by their best next effect where the round's best single leaves the
/// misfit above the noise level: the best single and the round's next significant refits by
/// margin. Each costs one ranking and [`PAIR_PARTNERS`] refits.
pub(crate) const PAIR_FIRSTS: usize = 3;

/// Next effects refitted for each first effect: the leading families of the ranking with the
/// first effect in (one refit each, exploring its starts as a round's leaders do).
pub(crate) const PAIR_PARTNERS: usize = 3;

/// The margin (likelihood ratio over its critical value at the round's threshold) by which
/// another first effect's pair must stand above the best single's own pair to take the single's
/// place: χ² with 1 degree of freedom at 95 %, the level at which the diagnosis says the data
/// tell two refits apart ([`EQUIVALENT_LR`]).
pub(crate) const PAIR_LEVEL: f64 = EQUIVALENT_LR;
