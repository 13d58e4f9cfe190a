//! Torque-ripple compensation: q-current feed-forward, indexed by the
//! measured shaft angle, against the machine's angle-locked ripple (paper
//! section 3.3). Four strategies behind one interface, chosen at run time
//! with [`Strategy`]:
//!
//! 1. [`Strategy::Table`]: an offline harmonic table (Fourier coefficients per
//!    mechanical order), identified from a calibration travel
//!    ([`RippleCompensator::learned_table`] after a travel with
//!    [`Strategy::Adaptive`]) and applied as it is.
//! 2. [`Strategy::Adaptive`]: per-harmonic normalised LMS during the travel,
//!    its error the speed-loop error demodulated at each order, with the
//!    phase correction from the model ([`response::loop_response`]).
//! 3. [`Strategy::Learning`]: iterative learning across travels, the
//!    coefficients indexed by position ([`learning`]).
//! 4. [`Strategy::CarObserver`]: the same learning law driven by the
//!    observer's car-acceleration estimate and the model's car response, so it
//!    aims at the car rather than at the shaft.
//!
//! Learning law (strategies 2 and 4), per speed-loop tick and harmonic `n`:
//! the error `e` (speed error, rad/s, or car acceleration, m/s^2) is
//! demodulated, `E = 2 e e^{-j n theta}`, and turned into a residual ripple
//! estimate `R = conj(G) E / (|G|^2 + eps)` (N m), with `G` the model's
//! response of `e` to a shaft torque at that order's frequency; then
//! `U <- U - mu R`. If the true response is `G'`, the residual `T + U`
//! decays as `exp(-mu f_s Re(G'/G) t)`: stable for any model error of phase
//! under 90 degrees, time constant `1 / (mu f_s)` = 0.25 s when the model is
//! right.
//!
//! Safety (all strategies): each harmonic's demodulated error is averaged
//! (time constant 0.25 s or four periods of the order, whichever is longer)
//! and divided by the model response, an unbiased residual estimate `R`. If
//! the residual with the compensation is not at least 2 dB under the
//! estimated ripple without it (`|R| > 0.8 |R - U|`) for a net 0.125 s while the response is
//! above its floor (where `R` can be trusted), that harmonic backs off: its
//! output goes to zero for the rest of the travel and it stops learning
//! ([`RippleCompensator::backed_off`]). A learned coefficient that runs into
//! its limit backs off too.
//!
//! Weak responses: the learning step uses `conj(G) E / (|G|^2 + floor^2)`,
//! so an order the encoder sees poorly learns slowly instead of amplifying
//! noise, and an order under [`UNOBSERVABLE_FRACTION`] of the floor (72 at
//! rated speed: |G| ~ 8e-4 rad/s per N m against 3e-3) is not learned at
//! all: what it would learn is the model's bias there (iterative learning
//! drove it to 4x the true 72nd-order ripple before this rule). The time
//! constant also spans at least four periods of the order.

pub mod complex;
pub mod harmonics;
pub mod learning;
pub mod response;

use complex::Complex;
use harmonics::{HarmonicCurrent, HarmonicTable, MAX_HARMONICS};
use learning::{limit, LearningTable};

use crate::config::DriveConfig;
use crate::fixed::Q16;
use crate::observer::ChainModel;
use crate::trig::{sin_cos, Angle};

/// Compensation strategy.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Strategy {
    /// No compensation.
    Off,
    /// offline harmonic table.
    Table,
    /// adaptive angle-indexed harmonics (LMS) during the travel.
    Adaptive,
    /// iterative learning across travels, by position.
    Learning,
    /// adaptive harmonics driven by the observer's car acceleration.
    CarObserver,
}

impl Strategy {
    /// All strategies, `Off` first.
    pub const ALL: [Strategy; 5] =
        [Strategy::Off, Strategy::Table, Strategy::Adaptive, Strategy::Learning, Strategy::CarObserver];

    /// Numeric code (frames, recordings): 0 off .. 4 car observer.
    pub fn code(self) -> u8 {
        match self {
            Strategy::Off => 0,
            Strategy::Table => 1,
            Strategy::Adaptive => 2,
            Strategy::Learning => 3,
            Strategy::CarObserver => 4,
        }
    }

    /// The strategy of a [`Strategy::code`].
    pub fn from_code(code: u8) -> Option<Self> {
        Self::ALL.get(code as usize).copied()
    }

    /// Short name (`off`, `table`, `adaptive`, `learning`, `car-observer`).
    pub fn name(self) -> &'static str {
        match self {
            Strategy::Off => "off",
            Strategy::Table => "table",
            Strategy::Adaptive => "adaptive",
            Strategy::Learning => "learning",
            Strategy::CarObserver => "car-observer",
        }
    }
}

/// Largest LMS step per speed-loop tick (dimensionless): time constant
/// `1 / (mu f_s)` = 0.25 s at 2 kHz.
pub const LMS_STEP: f32 = 1.0 / 500.0;
/// The LMS time constant spans at least this many periods of the order.
pub const LMS_CYCLES: f32 = 4.0;
/// Largest averaging factor of the demodulated error per tick
/// (dimensionless): time constant 0.25 s at 2 kHz.
pub const RESIDUAL_AVERAGING: f32 = 1.0 / 500.0;
/// The residual average spans at least this many periods of the order.
pub const AVERAGING_CYCLES: f32 = 4.0;
/// Speed-error response below which learning slows down, rad/s per N m:
/// `R = conj(G) E / (|G|^2 + floor^2)`.
pub const SPEED_RESPONSE_FLOOR: f32 = 0.01;
/// An order whose response is under this fraction of the floor is not
/// learned (the 72nd at rated speed: |G| ~ 8e-4 rad/s per N m, under 3e-3).
pub const UNOBSERVABLE_FRACTION: f32 = 0.3;
/// Car-acceleration response below which learning slows down, m/s^2 per N m.
pub const CAR_RESPONSE_FLOOR: f32 = 0.05;
/// Time a harmonic takes to fade in at the start of a travel or out when it backs off, s.
pub const FADE_S: f32 = 0.05;
/// Highest frequency `Strategy::CarObserver` learns at, Hz: the reduced observer's
/// car estimate is good around the first two elastic modes (10-24 Hz).
pub const CAR_OBSERVER_MAX_HZ: f32 = 25.0;
/// Largest inductive voltage `L_q n w_rated |U| / Kt` one harmonic may ask
/// of the current loop at rated speed, V: a quarter of the supervisor's
/// back-EMF margin (`supervisor::BACK_EMF_LIMIT_FRACTION` of the rated
/// back-EMF, 4.15 V on the rig) per harmonic is 1 V; 1.5 V lets the 12th
/// order reach 5.5 N m (the rig's 3.5 N m plus 57 %) and caps the 72nd at 0.9 N m.
pub const HARMONIC_VOLTAGE_BUDGET_V: f32 = 1.5;
/// Back-off ratio on squared magnitudes: 0.64 (-2 dB). A harmonic that
/// gains less than 2 dB over no compensation is off before it can be worse
/// (a table whose phase drifts: at 47 degrees instead of 60).
pub const BACK_OFF_RATIO_SQ: f32 = 0.64;
/// Net ticks a harmonic must look worse before it backs off (0.125 s at
/// 2 kHz): a tick that looks worse counts up, one that does not counts down.
pub const BACK_OFF_TICKS: u16 = 250;
/// Learning runs only above this fraction of the rated shaft speed: at
/// constant speed, where the orders are steady lines (while the speed sweeps,
/// the large 12th order leaks into the weak orders' estimates).
pub const LEARNING_SPEED_FRACTION: f32 = 0.9;

/// Largest coefficient per harmonic of `orders`, N m: a tenth of the torque
/// limit, and no more than [`HARMONIC_VOLTAGE_BUDGET_V`] of inductive
/// voltage at rated speed.
fn harmonic_limits_nm(config: &DriveConfig, orders: &[u16]) -> [f32; MAX_HARMONICS] {
    let kt = config.torque_constant_nm_per_a();
    let overall = 0.1 * config.max_current_a * kt;
    let mut limits = [overall; MAX_HARMONICS];
    for (slot, &order) in limits.iter_mut().zip(orders) {
        let volts_per_nm = config.lq_h * order as f32 * config.rated_shaft_speed_radps() / kt;
        if volts_per_nm > 0.0 {
            *slot = overall.min(HARMONIC_VOLTAGE_BUDGET_V / volts_per_nm);
        }
    }
    limits
}

/// What the compensator learns from, once per speed-loop tick of a travel.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LearningInput {
    /// Shaft angle within the revolution (binary angle).
    pub shaft_angle: Angle,
    /// Shaft position since power-up, counts.
    pub position_counts: i64,
    /// Estimated shaft speed, rad/s.
    pub speed_radps: f32,
    /// Speed-loop error `speed_ref - speed` (position loop included), rad/s.
    pub speed_error_radps: f32,
    /// The observer's car acceleration, m/s^2 (`Strategy::CarObserver`), if available.
    pub car_acceleration_mps2: Option<f32>,
    /// The observer's identified rope `EA`, N, if available: the response
    /// model uses it instead of the nominal.
    pub rope_ea_n: Option<f32>,
    /// Car mass of the travel, kg.
    pub m_car_kg: f32,
    /// Counterweight-side rope length, m.
    pub lw_m: f32,
    /// Inertia the speed loop is tuned on, kg m^2.
    pub inertia_kg_m2: f32,
}

/// The compensator: one of the [`Strategy`]s and its state.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RippleCompensator {
    config: DriveConfig,
    /// The drive's model of the chain (phase correction).
    chain: ChainModel,
    strategy: Strategy,
    /// the `Strategy::Table` table, N m.
    table: HarmonicTable,
    /// Strategies 2 and 4: coefficients learned this travel, N m.
    adaptive: HarmonicTable,
    /// coefficients by position.
    learning: LearningTable,
    /// What is applied now, N m.
    applied: HarmonicTable,
    /// Its 16 kHz form.
    current: HarmonicCurrent,
    /// Model response per harmonic (refreshed one harmonic per tick).
    response: [Complex; MAX_HARMONICS],
    /// Averaged demodulated error `2 e e^{-j n theta}` (units of the error).
    demodulated: [Complex; MAX_HARMONICS],
    /// Residual ripple estimate `T + U` from the averaged error, N m.
    residual_nm: [Complex; MAX_HARMONICS],
    worse_ticks: [u16; MAX_HARMONICS],
    backed_off: [bool; MAX_HARMONICS],
    /// Fade of each harmonic's output, 0..1.
    fade: [f32; MAX_HARMONICS],
    ticks: u32,
    /// Angle the 16 kHz evaluation leads the measured angle by (current-loop lag).
    lead: Angle,
    /// Largest coefficient magnitude per harmonic, N m: a tenth of the
    /// torque limit, and within [`HARMONIC_VOLTAGE_BUDGET_V`].
    limit_nm: [f32; MAX_HARMONICS],
    /// Whether harmonics that make things worse back off (on by default).
    back_off_enabled: bool,
    /// The input of the latest speed-loop tick whose learning is not done
    /// yet ([`RippleCompensator::finish_tick`]).
    pending: Option<LearningInput>,
}

impl RippleCompensator {
    /// A compensator of the drive `config` on the chain `chain` for `orders`
    /// (mechanical orders, at most [`MAX_HARMONICS`]) with `strategy`, empty tables.
    pub fn new(config: &DriveConfig, chain: &ChainModel, orders: &[u16], strategy: Strategy) -> Self {
        let zero = HarmonicTable::zero(orders);
        Self {
            config: *config,
            chain: *chain,
            strategy,
            table: zero,
            adaptive: zero,
            learning: LearningTable::default(),
            applied: zero,
            current: HarmonicCurrent::default(),
            response: [Complex::ZERO; MAX_HARMONICS],
            demodulated: [Complex::ZERO; MAX_HARMONICS],
            residual_nm: [Complex::ZERO; MAX_HARMONICS],
            worse_ticks: [0; MAX_HARMONICS],
            backed_off: [false; MAX_HARMONICS],
            fade: [0.0; MAX_HARMONICS],
            ticks: 0,
            lead: 0,
            limit_nm: harmonic_limits_nm(config, orders),
            back_off_enabled: true,
            pending: None,
        }
    }

    /// Makes this compensator what `new(config, chain, orders of table,
    /// strategy)` and then [`RippleCompensator::set_table`] of `table`
    /// would make it, on the same drive configuration, in place: no
    /// second copy of its 8 KB (the learning table) is built, so the
    /// firmware can install a strategy inside its control interrupt.
    pub fn reinstall(&mut self, chain: &ChainModel, table: &HarmonicTable, strategy: Strategy) {
        self.pending = None;
        self.chain = *chain;
        self.strategy = strategy;
        self.current = HarmonicCurrent::default();
        self.response = [Complex::ZERO; MAX_HARMONICS];
        self.demodulated = [Complex::ZERO; MAX_HARMONICS];
        self.residual_nm = [Complex::ZERO; MAX_HARMONICS];
        self.worse_ticks = [0; MAX_HARMONICS];
        self.backed_off = [false; MAX_HARMONICS];
        self.fade = [0.0; MAX_HARMONICS];
        self.ticks = 0;
        self.lead = 0;
        self.back_off_enabled = true;
        self.table = *table;
        self.limit_nm = harmonic_limits_nm(&self.config, &table.orders[..table.len.min(MAX_HARMONICS)]);
        self.adaptive = HarmonicTable { torque_nm: [Complex::ZERO; MAX_HARMONICS], ..*table };
        self.applied = self.adaptive;
        self.learning.clear();
    }

    /// Enables or disables the back-off (disable only to measure, e.g. a
    /// response to a known injected table on a plant without ripple).
    pub fn set_back_off(&mut self, enabled: bool) {
        self.back_off_enabled = enabled;
    }

    /// The strategy in use.
    pub fn strategy(&self) -> Strategy {
        self.strategy
    }

    /// Switches strategy (between travels); the learned state is kept.
    pub fn set_strategy(&mut self, strategy: Strategy) {
        self.finish_tick();
        self.strategy = strategy;
    }

    /// Sets the `Strategy::Table` table (N m); its orders become the compensator's.
    pub fn set_table(&mut self, table: HarmonicTable) {
        self.finish_tick();
        self.table = table;
        self.limit_nm = harmonic_limits_nm(&self.config, &table.orders[..table.len.min(MAX_HARMONICS)]);
        self.adaptive = HarmonicTable { torque_nm: [Complex::ZERO; MAX_HARMONICS], ..table };
        self.applied = self.adaptive;
        self.learning = LearningTable::default();
    }

    /// the `Strategy::Table` table.
    pub fn table(&self) -> HarmonicTable {
        self.table
    }

    /// The coefficients learned by `Strategy::Adaptive` or `Strategy::CarObserver` in the last travel: what
    /// a calibration travel gives `Strategy::Table`.
    pub fn learned_table(&self) -> HarmonicTable {
        self.adaptive
    }

    /// The coefficients applied now, N m.
    pub fn applied(&self) -> HarmonicTable {
        self.applied
    }

    /// Strategy 3's coefficient of harmonic `k` at `position_counts` (from power-up), N m.
    pub fn learning_torque_at(&self, k: usize, position_counts: i64) -> Complex {
        self.learning.torque_at(k, position_counts, self.config.encoder_counts_per_rev)
    }

    /// Harmonics that backed off in this travel.
    pub fn backed_off(&self) -> [bool; MAX_HARMONICS] {
        self.backed_off
    }

    /// Averaged residual ripple estimate `T + U` per harmonic, N m.
    pub fn residual_nm(&self) -> [Complex; MAX_HARMONICS] {
        self.residual_nm
    }

    /// Start of a travel: back-off flags and averages cleared; the adaptive
    /// strategies start from zero, the table and the learned table are kept.
    pub fn start_travel(&mut self) {
        self.finish_tick();
        self.backed_off = [false; MAX_HARMONICS];
        self.fade = [0.0; MAX_HARMONICS];
        self.worse_ticks = [0; MAX_HARMONICS];
        self.residual_nm = [Complex::ZERO; MAX_HARMONICS];
        self.demodulated = [Complex::ZERO; MAX_HARMONICS];
        self.ticks = 0;
        self.adaptive.torque_nm = [Complex::ZERO; MAX_HARMONICS];
        self.applied.torque_nm = [Complex::ZERO; MAX_HARMONICS];
        self.current = HarmonicCurrent::default();
    }

    /// End of a travel: `Strategy::Learning` learns from it.
    pub fn end_travel(&mut self) {
        self.finish_tick();
        if self.strategy == Strategy::Learning {
            // At least a quarter revolution of samples at the learning speed.
            let rated = self.config.rated_shaft_speed_radps();
            let per_rev = self.config.speed_loop_hz * core::f32::consts::TAU / rated;
            self.learning.end_travel(self.applied.len, (0.25 * per_rev) as u16, &self.limit_nm, SPEED_RESPONSE_FLOOR);
            for k in 0..self.applied.len {
                if self.backed_off[k] {
                    self.learning.clear_harmonic(k);
                }
            }
        }
        self.current = HarmonicCurrent::default();
    }

    /// Compensation q current at the measured shaft angle, A (16 kHz path).
    pub fn iq_a(&self, shaft_angle: Angle) -> Q16 {
        if self.strategy == Strategy::Off {
            return Q16::ZERO;
        }
        self.current.at(shaft_angle.wrapping_add(self.lead))
    }

    /// One speed-loop tick of a travel: the coefficients of the next
    /// 16 kHz periods (fade, lead); the learning and the back-off of the
    /// tick are left for [`RippleCompensator::finish_tick`], which the
    /// controller runs once the step's outputs are out
    /// (`Controller::finish_step`). Splitting changes no bit: the learning
    /// of tick `k` changes only what tick `k + 1` reads (the adaptive
    /// coefficients, the back-off flags, the averages, the responses), and
    /// every tick, travel start or end and strategy or table change
    /// finishes the pending learning first.
    pub fn speed_tick(&mut self, input: &LearningInput) {
        self.finish_tick();
        let n = self.applied.len;
        if self.strategy == Strategy::Off || n == 0 {
            return;
        }
        self.update_lead(input.speed_radps);
        for k in 0..n {
            self.fade_applied(k, input);
        }
        let c = &self.config;
        self.current =
            HarmonicCurrent::from_table(&self.applied, c.torque_constant_nm_per_a(), &[false; MAX_HARMONICS]);
        self.pending = Some(*input);
    }

    /// The learning of the latest speed-loop tick, if not done yet: the
    /// model response of one harmonic refreshed, then each harmonic learns
    /// from the tick's error with the coefficient it had in force, and the
    /// back-off judges it.
    pub fn finish_tick(&mut self) {
        let Some(input) = self.pending.take() else {
            return;
        };
        let n = self.applied.len;
        self.refresh_response(&input, n);
        let tick = self.tick_learning(&input, n);
        for k in 0..n {
            if !tick.learns || self.backed_off[k] {
                continue;
            }
            let applied = self.applied.torque_nm[k];
            self.learn_harmonic(k, &input, &tick, applied);
        }
    }

    /// The angle lead of the 16 kHz path at `speed_radps` (rad/s): the
    /// current loop's lag (1 / wc) and 1.5 PWM periods of sampling and update.
    fn update_lead(&mut self, speed_radps: f32) {
        let c = &self.config;
        let lead_s = 1.0 / (core::f32::consts::TAU * c.current_loop_bandwidth_hz) + 1.5 / c.current_loop_hz;
        let lead_turns = speed_radps * lead_s * (1.0 / core::f32::consts::TAU);
        self.lead = (lead_turns * 4_294_967_296.0) as i32 as u32;
    }

    /// Refreshes one of the `n` harmonics' model response per tick (round
    /// robin), on the observer's EA where there is one.
    fn refresh_response(&mut self, input: &LearningInput, n: usize) {
        let c = &self.config;
        let mut chain = self.chain;
        if let Some(ea) = input.rope_ea_n.filter(|ea| ea.is_finite() && *ea > 0.0) {
            chain.rope_ea_n = ea;
        }
        let k_refresh = (self.ticks % n as u32) as usize;
        let omega = input.speed_radps * self.applied.orders[k_refresh] as f32;
        let response = response::loop_response(c, &chain, input.m_car_kg, input.lw_m, input.inertia_kg_m2, omega);
        self.response[k_refresh] = match self.strategy {
            Strategy::CarObserver => response.car_acceleration_per_torque,
            _ => response.speed_error_per_torque,
        };
        self.ticks = self.ticks.wrapping_add(1);
    }

    /// What this tick learns from, the same for all `n` harmonics.
    fn tick_learning(&self, input: &LearningInput, n: usize) -> TickLearning {
        let c = &self.config;
        let learning_speed = LEARNING_SPEED_FRACTION * c.rated_shaft_speed_radps();
        let fast_enough = input.speed_radps > learning_speed || input.speed_radps < -learning_speed;
        let (error, floor) = match (self.strategy, input.car_acceleration_mps2) {
            (Strategy::CarObserver, Some(a)) => (a, CAR_RESPONSE_FLOOR),
            (Strategy::CarObserver, None) => (0.0, CAR_RESPONSE_FLOOR),
            _ => (input.speed_error_radps, SPEED_RESPONSE_FLOOR),
        };
        let have_error = self.strategy != Strategy::CarObserver || input.car_acceleration_mps2.is_some();
        let refreshed_all = self.ticks >= n as u32;
        let speed_abs = if input.speed_radps < 0.0 { -input.speed_radps } else { input.speed_radps };
        let cycles_per_tick = speed_abs * (1.0 / core::f32::consts::TAU) / c.speed_loop_hz;
        TickLearning { learns: fast_enough && refreshed_all && have_error, error, floor, cycles_per_tick }
    }

    /// Harmonic `k`'s applied coefficient for this tick, N m, faded in at
    /// the start and out on back-off: a step in a harmonic current is a step
    /// in the current loop's voltage, which the back-EMF check would see.
    fn fade_applied(&mut self, k: usize, input: &LearningInput) -> Complex {
        let c = &self.config;
        let base = match self.strategy {
            Strategy::Table => limit(self.table.torque_nm[k], self.limit_nm[k]),
            Strategy::Adaptive | Strategy::CarObserver => self.adaptive.torque_nm[k],
            Strategy::Learning => self.learning.torque_at(k, input.position_counts, c.encoder_counts_per_rev),
            Strategy::Off => Complex::ZERO,
        };
        let fade_step = 1.0 / (FADE_S * c.speed_loop_hz);
        self.fade[k] = if self.backed_off[k] {
            if self.fade[k] > fade_step {
                self.fade[k] - fade_step
            } else {
                0.0
            }
        } else {
            (self.fade[k] + fade_step).min(1.0)
        };
        let applied = base.scale(self.fade[k]);
        self.applied.torque_nm[k] = applied;
        applied
    }

    /// Harmonic `k` learns from this tick's error (`tick`), the coefficient
    /// `applied` (N m) in force; then the back-off judges it.
    fn learn_harmonic(&mut self, k: usize, input: &LearningInput, tick: &TickLearning, applied: Complex) {
        let c = &self.config;
        let (error, floor) = (tick.error, tick.floor);
        let (s, co) = sin_cos(input.shaft_angle.wrapping_mul(self.applied.orders[k] as u32));
        let demodulated = Complex::new(co.to_num::<f32>(), -s.to_num::<f32>()).scale(2.0 * error);
        if !demodulated.is_finite() {
            return;
        }
        // Averages span at least LMS_CYCLES (learning) and AVERAGING_CYCLES (back-off) periods of the order.
        let cycles = tick.cycles_per_tick * self.applied.orders[k] as f32;
        let step = LMS_STEP.min(cycles * (1.0 / LMS_CYCLES));
        // Strategy 4 learns four times slower: its error is an estimate with a loop of its own.
        let step = if self.strategy == Strategy::CarObserver { 0.25 * step } else { step };
        let averaging = RESIDUAL_AVERAGING.min(cycles * (1.0 / AVERAGING_CYCLES));
        self.demodulated[k] = self.demodulated[k] + (demodulated - self.demodulated[k]).scale(averaging);
        let g = self.response[k];
        // An order the error hardly responds to is not learned at all:
        // whatever it would learn would be the bias of the model there.
        // Strategy 4 learns only orders the car answers at least `floor` to,
        // below CAR_OBSERVER_MAX_HZ: above, the observer's car estimate
        // follows its own ripple states, and learning from it closes a
        // loop that runs away (36th order, EA x0.8, 33 kg).
        let car = self.strategy == Strategy::CarObserver;
        let fraction = if car { 1.0 } else { UNOBSERVABLE_FRACTION };
        let too_fast = car && cycles * c.speed_loop_hz > CAR_OBSERVER_MAX_HZ;
        if too_fast || g.norm_sqr() < fraction * fraction * floor * floor {
            return;
        }
        // Regularised inverse: a response below the floor learns slower instead of amplifying noise.
        let shrunk = g.conj() * demodulated.scale(1.0 / (g.norm_sqr() + floor * floor));
        match self.strategy {
            Strategy::Adaptive | Strategy::CarObserver => {
                let next = self.adaptive.torque_nm[k] - shrunk.scale(step);
                // A coefficient that runs into its limit is not converging: back off.
                if next.norm_sqr() > self.limit_nm[k] * self.limit_nm[k] && self.back_off_enabled {
                    self.backed_off[k] = true;
                    return;
                }
                self.adaptive.torque_nm[k] = limit(next, self.limit_nm[k]);
            }
            Strategy::Learning => self.learning.accumulate(
                k,
                input.position_counts,
                c.encoder_counts_per_rev,
                g.conj() * demodulated,
                g.norm_sqr(),
            ),
            _ => {}
        }
        self.judge_back_off(k, g, floor, applied);
    }

    /// Worse than without? Harmonic `k` (loop response `g`, response floor
    /// `floor`) with the coefficient `applied` (N m) in force: `|T + U|`
    /// against `|T| = |R - U|`, `R` the unbiased residual; backed off after
    /// [`BACK_OFF_TICKS`] ticks more worse than better.
    fn judge_back_off(&mut self, k: usize, g: Complex, floor: f32, applied: Complex) {
        let residual = self.demodulated[k] / g;
        self.residual_nm[k] = residual;
        let with = residual.norm_sqr();
        let without = (residual - applied).norm_sqr();
        // Judged only where the response is strong enough for the estimate to mean something.
        let judged = g.norm_sqr() >= floor * floor;
        if self.back_off_enabled && judged && applied != Complex::ZERO && with > BACK_OFF_RATIO_SQ * without {
            self.worse_ticks[k] = self.worse_ticks[k].saturating_add(1);
            if self.worse_ticks[k] >= BACK_OFF_TICKS {
                self.backed_off[k] = true;
            }
        } else {
            self.worse_ticks[k] = self.worse_ticks[k].saturating_sub(1);
        }
    }
}

/// What one speed-loop tick learns from, the same for every harmonic.
struct TickLearning {
    /// Fast enough, every response refreshed, and an error to learn from.
    learns: bool,
    /// The error the harmonics learn from: speed error, rad/s, or the
    /// observer's car acceleration, m/s^2 (`Strategy::CarObserver`).
    error: f32,
    /// Response below which an order learns slower, in the error's unit per N m.
    floor: f32,
    /// Shaft revolutions per speed-loop tick.
    cycles_per_tick: f32,
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;

    fn rig() -> DriveConfig {
        crate::config::reference_rig()
    }

    fn chain() -> ChainModel {
        crate::config::reference_chain()
    }

    #[test]
    fn a_table_is_applied_as_its_q_current() {
        let config = rig();
        let mut table = HarmonicTable::default();
        table.push_cosine(12, 1.0, 1.0, 0.0);
        let mut c = RippleCompensator::new(&config, &chain(), &[12], Strategy::Table);
        c.set_table(table);
        c.start_travel();
        let input = LearningInput {
            shaft_angle: 0,
            position_counts: 0,
            speed_radps: 0.0,
            speed_error_radps: 0.0,
            car_acceleration_mps2: None,
            rope_ea_n: None,
            m_car_kg: 70.5,
            lw_m: 4.0,
            inertia_kg_m2: 1.0,
        };
        // Faded in over FADE_S: at half of it, half the table; after it, all of it.
        let ticks = (FADE_S * config.speed_loop_hz) as usize;
        for _ in 0..ticks / 2 {
            c.speed_tick(&input);
        }
        let half = c.applied().torque_nm[0].re;
        assert!((half - 0.5).abs() < 0.02, "{half}");
        for _ in 0..ticks {
            c.speed_tick(&input);
        }
        let peak = (0..1000u32).map(|i| c.iq_a(i * 4_294_967).to_num::<f64>()).fold(0.0f64, |m, v| m.max(v.abs()));
        let expected = 1.0 / config.torque_constant_nm_per_a() as f64;
        assert!((peak - expected).abs() < 1e-3 * expected, "{peak} vs {expected}");
    }

    #[test]
    fn a_reinstalled_compensator_is_a_new_one() {
        let config = rig();
        let mut first = HarmonicTable::default();
        first.push_cosine(12, 1.0, 1.0, 0.0);
        first.push_cosine(36, 0.2, 0.0, 1.0);
        let mut c = RippleCompensator::new(&config, &chain(), &first.orders[..first.len], Strategy::Adaptive);
        c.set_table(first);
        c.set_back_off(false);
        c.start_travel();
        // Learn something: fast enough, with a speed error.
        for k in 0..2000u32 {
            c.speed_tick(&LearningInput {
                shaft_angle: k.wrapping_mul(97_000_000),
                position_counts: k as i64 * 40,
                speed_radps: 6.0,
                speed_error_radps: 0.01 * ((k % 7) as f32 - 3.0),
                car_acceleration_mps2: None,
                rope_ea_n: None,
                m_car_kg: 70.5,
                lw_m: 4.0,
                inertia_kg_m2: 1.0,
            });
        }
        assert_ne!(
            c.learned_table(),
            RippleCompensator::new(&config, &chain(), &[12, 36], Strategy::Adaptive).learned_table()
        );
        let mut second = HarmonicTable::default();
        second.push_cosine(6, 0.5, 0.0, 1.0);
        let mut other_chain = chain();
        other_chain.rope_ea_n *= 0.9;
        c.reinstall(&other_chain, &second, Strategy::Learning);
        let mut fresh = RippleCompensator::new(&config, &other_chain, &second.orders[..second.len], Strategy::Learning);
        fresh.set_table(second);
        assert_eq!(c, fresh);
    }
}
