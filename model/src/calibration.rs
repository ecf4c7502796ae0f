//! Vibrator calibration, Eqs. (15)-(17) and Table 2: torque from current, the vibrator's own
//! loss, and the no-load current; its plausibility against the motor's own constants
//! ([`Calibration::check`]) and the board's caps on the limits a calibration asks for
//! ([`BoardLimits::check`]). Host (before sending) and firmware (before storing) run the
//! same two checks.

use core::fmt;

use crate::hardware::{self, MotorConstants};

/// Calibration constants C1-C6 of the vibrator, in SI units (N m, A, rad/s).
///
/// - |tau_cam| = C1 i_in + C2 (Eq. 15),
/// - |tau_loss| = C3 w_n + C4 (Eq. 16),
/// - |i_loss| = C5 w_n + C6 (Eq. 17).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct Calibration {
    /// C1, N m/A.
    pub c1: f64,
    /// C2, N m.
    pub c2: f64,
    /// C3, N m s/rad.
    pub c3: f64,
    /// C4, N m.
    pub c4: f64,
    /// C5, A s/rad.
    pub c5: f64,
    /// C6, A.
    pub c6: f64,
}

/// How well C3 and C4 agree with the values implied by C1, C2, C5 and C6.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CalibrationConsistency {
    /// C1 C5, N m s/rad (what C3 should be).
    pub c3_implied: f64,
    /// C1 C6 + C2, N m (what C4 should be).
    pub c4_implied: f64,
    /// |C3 - C1 C5| / |C3|.
    pub c3_rel_error: f64,
    /// |C4 - (C1 C6 + C2)| / |C4|.
    pub c4_rel_error: f64,
}

impl Calibration {
    /// Table 2 of the paper ([`crate::paper::CALIBRATION`]).
    pub const PAPER: Calibration = crate::paper::CALIBRATION;

    /// From the paper's units: C1 N mm/A, C2 N mm, C3 N mm s/rad, C4 N mm, C5 A s/rad, C6 A.
    pub const fn from_paper_units(c: [f64; 6]) -> Self {
        Self {
            c1: c[0] * 1e-3,
            c2: c[1] * 1e-3,
            c3: c[2] * 1e-3,
            c4: c[3] * 1e-3,
            c5: c[4],
            c6: c[5],
        }
    }

    /// In the paper's units, `[C1, .., C6]` (see [`Calibration::from_paper_units`]).
    pub fn to_paper_units(&self) -> [f64; 6] {
        [
            self.c1 * 1e3,
            self.c2 * 1e3,
            self.c3 * 1e3,
            self.c4 * 1e3,
            self.c5,
            self.c6,
        ]
    }

    /// Vibrator from C1, C2 (torque-current) and C5, C6 (no-load current), with C3 and C4
    /// derived as the torque of the no-load current: C3 = C1 C5, C4 = C1 C6 + C2.
    pub fn from_torque_and_no_load(c1: f64, c2: f64, c5: f64, c6: f64) -> Self {
        Self {
            c1,
            c2,
            c3: c1 * c5,
            c4: c1 * c6 + c2,
            c5,
            c6,
        }
    }

    /// Gross shaft torque for input current `i_in` (A), Eq. (15), N m.
    pub fn gross_torque(&self, i_in: f64) -> f64 {
        self.c1 * i_in + self.c2
    }

    /// The vibrator's own loss torque at cam speed `omega_n` (rad/s), Eq. (16), N m.
    pub fn loss_torque(&self, omega_n: f64) -> f64 {
        self.c3 * omega_n.abs() + self.c4
    }

    /// No-load current at cam speed `omega_n`, Eq. (17), A.
    pub fn no_load_current(&self, omega_n: f64) -> f64 {
        self.c5 * omega_n.abs() + self.c6
    }

    /// Torque reaching the cam under load: tau_cam = C1 i + C2 - (C3 w_n + C4), N m.
    pub fn cam_torque(&self, i_in: f64, omega_n: f64) -> f64 {
        self.gross_torque(i_in) - self.loss_torque(omega_n)
    }

    /// Current that delivers cam torque `tau_cam` at `omega_n` (inverse of [`Self::cam_torque`]), A.
    pub fn current_for(&self, tau_cam: f64, omega_n: f64) -> f64 {
        (tau_cam + self.loss_torque(omega_n) - self.c2) / self.c1
    }

    /// Consistency of C3 and C4 with C1 C5 and C1 C6 + C2.
    pub fn consistency(&self) -> CalibrationConsistency {
        let c3_implied = self.c1 * self.c5;
        let c4_implied = self.c1 * self.c6 + self.c2;
        CalibrationConsistency {
            c3_implied,
            c4_implied,
            c3_rel_error: ((self.c3 - c3_implied) / self.c3).abs(),
            c4_rel_error: ((self.c4 - c4_implied) / self.c4).abs(),
        }
    }

    /// Whether every constant is finite and physically signed (C1, C3, C5, C6 > 0).
    pub fn is_plausible(&self) -> bool {
        let all = [self.c1, self.c2, self.c3, self.c4, self.c5, self.c6];
        all.iter().all(|c| c.is_finite())
            && self.c1 > 0.0
            && self.c3 >= 0.0
            && self.c5 >= 0.0
            && self.c6 > 0.0
    }

    /// Whether the constants are plausible for a vibrator with the motor constants `motor`:
    /// the first rule broken, naming the constant, or `Ok`. The rules, in order:
    ///
    /// 1. every constant is finite;
    /// 2. signs: C1 > 0, C2 <= 0 (a Coulomb loss), C3 >= 0, C5 >= 0, C6 > 0;
    /// 3. C1 lies within a factor [`C1_PLAUSIBLE_FACTOR`] of the motor's eta N Kt;
    /// 4. the no-load current C5 w + C6 at the motor's reference speed lies within a factor
    ///    [`NO_LOAD_PLAUSIBLE_FACTOR`] of the motor's no-load current (C6 and C5 w each at
    ///    most the upper end);
    /// 5. C3 = C1 C5 and C4 = C1 C6 + C2 (the loss torque is the torque of the no-load
    ///    current) within [`CONSISTENCY_TOLERANCE`] of their scale: for C3 the larger of
    ///    |C3| and |C1 C5|; for C4, a small difference of C1 C6 and -C2, the largest of |C4|,
    ///    |C1 C6 + C2| and 5 % of C1 C6 (what three printed digits of C1 and C6 leave).
    ///
    /// Table 2 passes (its C4 is 1.69 N mm against C1 C6 + C2 = 1.725); a C1 of 2258 N mm/A
    /// (36 times Table 2) fails naming C1.
    pub fn check(&self, motor: &MotorConstants) -> Result<(), CalibrationIssue> {
        check_constants(
            [self.c1, self.c2, self.c3, self.c4, self.c5, self.c6],
            motor.cam_torque_constant(),
            motor.no_load_current,
            motor.no_load_speed,
        )
    }
}

/// The arithmetic of [`check_constants`]: `f64` on the host, `f32` on the target, whose FPU
/// has no double precision (the same rules, no software double maths in the firmware).
pub trait CheckFloat:
    Copy
    + PartialOrd
    + core::ops::Add<Output = Self>
    + core::ops::Sub<Output = Self>
    + core::ops::Mul<Output = Self>
    + core::ops::Div<Output = Self>
{
    /// Zero.
    const ZERO: Self;
    /// A constant of the rules (folded at compile time).
    fn of(v: f64) -> Self;
    /// The value for a [`CalibrationIssue`], SI.
    fn to_f64(self) -> f64;
    /// Neither NaN nor infinite.
    fn finite(self) -> bool;
    /// Absolute value.
    fn magnitude(self) -> Self;
    /// The larger of two (NaN-ignoring, as `f64::max`).
    fn larger(self, other: Self) -> Self;
}

impl CheckFloat for f64 {
    const ZERO: Self = 0.0;
    fn of(v: f64) -> Self {
        v
    }
    fn to_f64(self) -> f64 {
        self
    }
    fn finite(self) -> bool {
        self.is_finite()
    }
    fn magnitude(self) -> Self {
        self.abs()
    }
    fn larger(self, other: Self) -> Self {
        self.max(other)
    }
}

impl CheckFloat for f32 {
    const ZERO: Self = 0.0;
    #[allow(
        clippy::cast_possible_truncation,
        reason = "the rules' constants and the motor's, well inside f32's range; rounded to nearest"
    )]
    fn of(v: f64) -> Self {
        v as f32
    }
    fn to_f64(self) -> f64 {
        f64::from(self)
    }
    fn finite(self) -> bool {
        self.is_finite()
    }
    fn magnitude(self) -> Self {
        self.abs()
    }
    fn larger(self, other: Self) -> Self {
        self.max(other)
    }
}

/// [`Calibration::check`]'s rules for C1-C6 `c` (SI) against a motor's cam torque constant
/// eta N Kt `kt` (N m/A), no-load current `i0` (A) and speed `w0` (rad/s), in the precision
/// `T`: the firmware evaluates them in `f32`, the host's [`Calibration::check`] in `f64`.
/// The first rule broken, naming the constant (values reported in SI as `f64`), or `Ok`.
pub fn check_constants<T: CheckFloat>(
    c: [T; 6],
    kt: T,
    i0: T,
    w0: T,
) -> Result<(), CalibrationIssue> {
    let [c1, c2, c3, c4, c5, c6] = c;
    for (field, v) in CalibrationField::ALL.into_iter().zip(c) {
        if !v.finite() {
            return Err(CalibrationIssue::new(
                field,
                v.to_f64(),
                IssueKind::NotFinite,
            ));
        }
    }
    let zero = T::ZERO;
    let sign = |field, ok: bool, must_be| {
        if ok {
            Ok(())
        } else {
            let v = c[field as usize];
            Err(CalibrationIssue::new(
                field,
                v.to_f64(),
                IssueKind::WrongSign { must_be },
            ))
        }
    };
    sign(CalibrationField::C1, c1 > zero, "positive")?;
    sign(CalibrationField::C2, c2 <= zero, "zero or negative")?;
    sign(CalibrationField::C3, c3 >= zero, "zero or positive")?;
    sign(CalibrationField::C5, c5 >= zero, "zero or positive")?;
    sign(CalibrationField::C6, c6 > zero, "positive")?;

    let range = |field, v: T, low: T, high: T| {
        if v >= low && v <= high {
            Ok(())
        } else {
            Err(CalibrationIssue::new(
                field,
                v.to_f64(),
                IssueKind::Implausible {
                    low: low.to_f64(),
                    high: high.to_f64(),
                },
            ))
        }
    };
    let c1_factor = T::of(C1_PLAUSIBLE_FACTOR);
    range(CalibrationField::C1, c1, kt / c1_factor, kt * c1_factor)?;
    let no_load_factor = T::of(NO_LOAD_PLAUSIBLE_FACTOR);
    let high = i0 * no_load_factor;
    range(CalibrationField::C6, c6, zero, high)?;
    range(CalibrationField::C5, c5, zero, high / w0)?;
    let viscous = c5 * w0;
    range(
        CalibrationField::C6,
        c6,
        i0 / no_load_factor - viscous,
        high - viscous,
    )?;

    // The consistency of Calibration::consistency.
    let c3_implied = c1 * c5;
    let c4_implied = c1 * c6 + c2;
    let tolerance = T::of(CONSISTENCY_TOLERANCE);
    let c3_tol = tolerance * c3.magnitude().larger(c3_implied.magnitude());
    if (c3 - c3_implied).magnitude() > c3_tol {
        return Err(CalibrationIssue::new(
            CalibrationField::C3,
            c3.to_f64(),
            IssueKind::Inconsistent {
                implied: c3_implied.to_f64(),
                tolerance: c3_tol.to_f64(),
            },
        ));
    }
    let c4_scale = c4
        .magnitude()
        .larger(c4_implied.magnitude())
        .larger(T::of(0.05) * (c1 * c6).magnitude());
    let c4_tol = tolerance * c4_scale;
    if (c4 - c4_implied).magnitude() > c4_tol {
        return Err(CalibrationIssue::new(
            CalibrationField::C4,
            c4.to_f64(),
            IssueKind::Inconsistent {
                implied: c4_implied.to_f64(),
                tolerance: c4_tol.to_f64(),
            },
        ));
    }
    Ok(())
}

impl Default for Calibration {
    fn default() -> Self {
        Self::PAPER
    }
}

/// C1 may lie within this factor of the motor's eta N Kt ([`Calibration::check`]): a torque
/// constant varies by some 10 % between motors and with temperature, a gearhead's efficiency
/// between about 0.5 and 0.9.
pub const C1_PLAUSIBLE_FACTOR: f64 = 2.0;

/// The no-load current C5 w + C6 may lie within this factor of the motor's
/// ([`Calibration::check`]).
pub const NO_LOAD_PLAUSIBLE_FACTOR: f64 = 2.0;

/// Relative tolerance of C3 = C1 C5 and C4 = C1 C6 + C2 ([`Calibration::check`]).
pub const CONSISTENCY_TOLERANCE: f64 = 0.10;

/// One of the constants C1-C6.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum CalibrationField {
    /// C1, torque per ampere.
    C1,
    /// C2, torque offset.
    C2,
    /// C3, viscous loss.
    C3,
    /// C4, constant loss.
    C4,
    /// C5, no-load current per cam speed.
    C5,
    /// C6, no-load current offset.
    C6,
}

impl CalibrationField {
    /// C1..C6 in order.
    pub const ALL: [CalibrationField; 6] = [
        CalibrationField::C1,
        CalibrationField::C2,
        CalibrationField::C3,
        CalibrationField::C4,
        CalibrationField::C5,
        CalibrationField::C6,
    ];

    /// The constant's name, `c1`..`c6`.
    pub const fn name(self) -> &'static str {
        match self {
            CalibrationField::C1 => "c1",
            CalibrationField::C2 => "c2",
            CalibrationField::C3 => "c3",
            CalibrationField::C4 => "c4",
            CalibrationField::C5 => "c5",
            CalibrationField::C6 => "c6",
        }
    }

    /// The constant's unit in the paper (Table 2).
    pub const fn paper_unit(self) -> &'static str {
        match self {
            CalibrationField::C1 => "N mm/A",
            CalibrationField::C2 | CalibrationField::C4 => "N mm",
            CalibrationField::C3 => "N mm s/rad",
            CalibrationField::C5 => "A s/rad",
            CalibrationField::C6 => "A",
        }
    }

    /// Factor from SI to the paper's unit (1e3 for the torques, 1 for the currents).
    pub const fn paper_scale(self) -> f64 {
        match self {
            CalibrationField::C5 | CalibrationField::C6 => 1.0,
            _ => 1e3,
        }
    }
}

/// Why a constant was refused ([`Calibration::check`]); values in SI.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum IssueKind {
    /// NaN or infinite.
    NotFinite,
    /// The constant has the wrong sign.
    WrongSign {
        /// What it must be ("positive", "zero or negative", ...).
        must_be: &'static str,
    },
    /// Outside the range plausible for the motor.
    Implausible {
        /// Lowest plausible value, SI.
        low: f64,
        /// Highest plausible value, SI.
        high: f64,
    },
    /// Disagrees with the value the other constants imply (C3 = C1 C5, C4 = C1 C6 + C2).
    Inconsistent {
        /// The implied value, SI.
        implied: f64,
        /// The largest difference accepted, SI.
        tolerance: f64,
    },
}

/// A calibration constant [`Calibration::check`] refuses: which, its value (SI) and why.
/// Its `Display` names the constant and the rule in the paper's units.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CalibrationIssue {
    /// The constant.
    pub field: CalibrationField,
    /// Its value, SI.
    pub value: f64,
    /// The rule it breaks.
    pub kind: IssueKind,
}

impl CalibrationIssue {
    fn new(field: CalibrationField, value: f64, kind: IssueKind) -> Self {
        Self { field, value, kind }
    }
}

impl fmt::Display for CalibrationIssue {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let (name, unit, k) = (
            self.field.name(),
            self.field.paper_unit(),
            self.field.paper_scale(),
        );
        if let IssueKind::NotFinite = self.kind {
            return write!(f, "{name} is not a finite number");
        }
        write!(f, "{name} = {} {unit} ", Sig(self.value * k))?;
        match self.kind {
            IssueKind::NotFinite => Ok(()),
            IssueKind::WrongSign { must_be } => {
                write!(f, "has the wrong sign: it must be {must_be}")
            }
            IssueKind::Implausible { low, high } => write!(
                f,
                "is outside the plausible range {} to {} {unit} for this vibrator motor",
                Sig(low * k),
                Sig(high * k)
            ),
            IssueKind::Inconsistent { implied, tolerance } => write!(
                f,
                "disagrees with {} = {} {unit} by more than {} {unit} (the vibrator's loss torque must be the torque of its no-load current)",
                if self.field == CalibrationField::C3 {
                    "C1 C5"
                } else {
                    "C1 C6 + C2"
                },
                Sig(implied * k),
                Sig(tolerance * k)
            ),
        }
    }
}

impl core::error::Error for CalibrationIssue {}

/// The board's caps on the limits a calibration asks for; also the shape of those limits.
/// A calibration may ask for less, never more ([`BoardLimits::check`]).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct BoardLimits {
    /// Largest load on the output while released, N m.
    pub max_release_load_nm: f64,
    /// Largest motor current, A.
    pub max_current_a: f64,
    /// Highest vibration frequency, Hz.
    pub max_freq_hz: f64,
}

impl BoardLimits {
    /// The paper's board and gear: the load at the teeth's strength
    /// ([`crate::paper::TAU_ROT_MAX`], 3.68 N m), the current at the ACS714's range (5 A),
    /// the frequency at the controller's highest (20 Hz).
    pub const PAPER: BoardLimits = BoardLimits {
        max_release_load_nm: crate::paper::TAU_ROT_MAX,
        max_current_a: hardware::acs714::RANGE_A,
        max_freq_hz: hardware::board::MAX_FREQ_HZ,
    };

    /// Whether `requested` (the limits a calibration asks for) is positive, finite and
    /// within these caps: the first field that is not, or `Ok` ([`check_limits`] in `f64`).
    pub fn check(&self, requested: &BoardLimits) -> Result<(), LimitIssue> {
        check_limits(
            [
                requested.max_release_load_nm,
                requested.max_current_a,
                requested.max_freq_hz,
            ],
            [
                self.max_release_load_nm,
                self.max_current_a,
                self.max_freq_hz,
            ],
        )
    }
}

/// [`BoardLimits::check`]'s rule in the precision `T`: `requested` and `caps` in the order
/// of [`LimitField`] (release load, current, frequency); the first requested limit that is
/// not finite, not positive or above its cap (values reported as `f64`), or `Ok`. The
/// firmware evaluates it in `f32` (its caps are `f32`, so the verdicts are those of the
/// `f64` check on the same numbers widened), the host in `f64`.
pub fn check_limits<T: CheckFloat>(requested: [T; 3], caps: [T; 3]) -> Result<(), LimitIssue> {
    let fields = [
        LimitField::MaxReleaseLoad,
        LimitField::MaxCurrent,
        LimitField::MaxFreq,
    ];
    for ((field, value), cap) in fields.into_iter().zip(requested).zip(caps) {
        let kind = if !value.finite() {
            LimitIssueKind::NotFinite
        } else if value <= T::ZERO {
            LimitIssueKind::NotPositive
        } else if value > cap {
            LimitIssueKind::AboveCap
        } else {
            continue;
        };
        return Err(LimitIssue {
            field,
            value: value.to_f64(),
            cap: cap.to_f64(),
            kind,
        });
    }
    Ok(())
}

impl Default for BoardLimits {
    fn default() -> Self {
        Self::PAPER
    }
}

/// One of the limits of [`BoardLimits`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum LimitField {
    /// `max_release_load_nm`.
    MaxReleaseLoad,
    /// `max_current_a`.
    MaxCurrent,
    /// `max_freq_hz`.
    MaxFreq,
}

impl LimitField {
    /// The field's name, as in calibration files and on the wire.
    pub const fn name(self) -> &'static str {
        match self {
            LimitField::MaxReleaseLoad => "max_release_load_nm",
            LimitField::MaxCurrent => "max_current_a",
            LimitField::MaxFreq => "max_freq_hz",
        }
    }

    /// The field's unit.
    pub const fn unit(self) -> &'static str {
        match self {
            LimitField::MaxReleaseLoad => "N m",
            LimitField::MaxCurrent => "A",
            LimitField::MaxFreq => "Hz",
        }
    }
}

/// Why a requested limit was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LimitIssueKind {
    /// NaN or infinite.
    NotFinite,
    /// Zero or negative.
    NotPositive,
    /// Above the board's cap.
    AboveCap,
}

/// A requested limit [`BoardLimits::check`] refuses. Its `Display` names the field and the
/// allowed range.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LimitIssue {
    /// The limit.
    pub field: LimitField,
    /// The requested value.
    pub value: f64,
    /// The board's cap.
    pub cap: f64,
    /// The rule it breaks.
    pub kind: LimitIssueKind,
}

impl fmt::Display for LimitIssue {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let (name, unit) = (self.field.name(), self.field.unit());
        match self.kind {
            LimitIssueKind::NotFinite => write!(f, "{name} is not a finite number")?,
            LimitIssueKind::NotPositive => {
                write!(f, "{name} = {} {unit} must be positive", Sig(self.value))?;
            }
            LimitIssueKind::AboveCap => write!(
                f,
                "{name} = {} {unit} is above the board's cap",
                Sig(self.value)
            )?,
        }
        write!(f, " (allowed: above 0 up to {} {unit})", Sig(self.cap))
    }
}

impl core::error::Error for LimitIssue {}

/// A number as a person writes it: four significant digits, no trailing zeros (62.1, not
/// 62.099999999999994), scientific notation outside 1e-4..1e7.
struct Sig(f64);

impl fmt::Display for Sig {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let x = self.0;
        if x == 0.0 || !x.is_finite() {
            return write!(f, "{x}");
        }
        let magnitude = libm::floor(libm::log10(x.abs()));
        if !(-4.0..7.0).contains(&magnitude) {
            return write!(f, "{x:.3e}");
        }
        #[allow(
            clippy::cast_possible_truncation,
            clippy::cast_sign_loss,
            reason = "magnitude is in -4..7 here, so 0 <= decimals <= 7"
        )]
        let decimals = (3.0 - magnitude).max(0.0) as usize;
        let mut buf = Buf::default();
        fmt::write(&mut buf, format_args!("{x:.decimals$}"))?;
        let mut s = buf.as_str();
        if s.contains('.') {
            s = s.trim_end_matches('0').trim_end_matches('.');
        }
        f.write_str(s)
    }
}

/// A small stack buffer for [`Sig`].
#[derive(Default)]
struct Buf {
    bytes: [u8; 32],
    len: usize,
}

impl Buf {
    fn as_str(&self) -> &str {
        core::str::from_utf8(&self.bytes[..self.len]).unwrap_or("?")
    }
}

impl fmt::Write for Buf {
    fn write_str(&mut self, s: &str) -> fmt::Result {
        let end = self.len + s.len();
        if end > self.bytes.len() {
            return Err(fmt::Error);
        }
        self.bytes[self.len..end].copy_from_slice(s.as_bytes());
        self.len = end;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn table2_is_self_consistent() {
        let c = Calibration::PAPER.consistency();
        // C1 C5 = 0.2347 N mm s/rad against C3 = 0.235.
        assert!((c.c3_implied * 1e3 - 0.2347).abs() < 1e-4);
        assert!(c.c3_rel_error < 0.005, "{}", c.c3_rel_error);
        // C1 C6 + C2 = 1.725 N mm against C4 = 1.69: a small difference of large numbers.
        assert!((c.c4_implied * 1e3 - 1.725).abs() < 1e-3);
        assert!(c.c4_rel_error < 0.03, "{}", c.c4_rel_error);
    }

    #[test]
    fn loss_torque_is_the_torque_of_the_no_load_current() {
        let c = Calibration::PAPER;
        for w in [10.0, 31.4, 62.8, 94.2] {
            let via_current = c.gross_torque(c.no_load_current(w));
            assert!((via_current - c.loss_torque(w)).abs() < 1e-4, "w {w}");
            // At no load the cam torque is (nearly) zero.
            assert!(c.cam_torque(c.no_load_current(w), w).abs() < 1e-4);
        }
    }

    #[test]
    fn current_for_inverts_cam_torque() {
        let c = Calibration::PAPER;
        let i = c.current_for(0.0535, 31.4);
        assert!((c.cam_torque(i, 31.4) - 0.0535).abs() < 1e-12);
        // ~3.2 A for the full 3.68 N m load at 5 Hz.
        assert!(i > 3.0 && i < 3.5, "{i}");
    }

    #[test]
    fn paper_units_round_trip() {
        let p = Calibration::PAPER.to_paper_units();
        let expected = [62.1, -138.0, 0.235, 1.69, 0.00378, 2.25];
        for (a, b) in p.iter().zip(expected) {
            assert!((a - b).abs() < 1e-9);
        }
        assert_eq!(
            Calibration::from_torque_and_no_load(1.0, -1.0, 2.0, 3.0).c4,
            2.0
        );
        assert!(Calibration::PAPER.is_plausible());
    }

    #[test]
    fn table2_is_plausible_for_the_rs735() {
        assert_eq!(Calibration::PAPER.check(&MotorConstants::RS735), Ok(()));
        // The plant's motor, calibrated, passes too.
        let plant = crate::plant::MotorParams::default().calibration();
        assert_eq!(plant.check(&MotorConstants::RS735), Ok(()));
    }

    #[test]
    fn f32_rules_agree_with_f64() {
        let m = MotorConstants::default();
        let mut cases = vec![Calibration::PAPER.to_paper_units()];
        for (k, f) in [(0, 36.0), (1, -1.0), (2, 1.5), (3, 0.5), (4, 3.0), (5, 0.1)] {
            let mut p = Calibration::PAPER.to_paper_units();
            p[k] *= f;
            cases.push(p);
        }
        for p in cases {
            let f64_verdict = Calibration::from_paper_units(p)
                .check(&m)
                .map_err(|e| e.field);
            #[allow(clippy::cast_possible_truncation, reason = "test values")]
            let si = Calibration::from_paper_units(p)
                .to_paper_units()
                .map(|v| v as f32);
            let si = [
                si[0] * 1e-3,
                si[1] * 1e-3,
                si[2] * 1e-3,
                si[3] * 1e-3,
                si[4],
                si[5],
            ];
            let of = <f32 as CheckFloat>::of;
            let f32_verdict = check_constants(
                si,
                of(m.cam_torque_constant()),
                of(m.no_load_current),
                of(m.no_load_speed),
            )
            .map_err(|e| e.field);
            assert_eq!(f32_verdict, f64_verdict, "{p:?}");
        }
    }

    #[test]
    fn a_fit_36_times_off_names_c1() {
        let mut c = Calibration::PAPER;
        c.c1 = 2258.0e-3;
        let e = c.check(&MotorConstants::RS735).unwrap_err();
        assert_eq!(e.field, CalibrationField::C1);
        assert!(matches!(e.kind, IssueKind::Implausible { .. }));
        let text = e.to_string();
        assert!(text.starts_with("c1 = 2258 N mm/A"), "{text}");
        assert!(text.contains("31.2 to 124.8 N mm/A"), "{text}");
        // Scaled consistently (C3, C4 derived), a C1 36 times off still fails on C1.
        let scaled =
            Calibration::from_torque_and_no_load(2258.0e-3, -138.0e-3 * 36.0, 0.00378, 2.25);
        assert_eq!(
            scaled.check(&MotorConstants::RS735).unwrap_err().field,
            CalibrationField::C1
        );
    }

    #[test]
    fn nan_and_signs_are_named() {
        let m = MotorConstants::RS735;
        for (k, field) in CalibrationField::ALL.into_iter().enumerate() {
            let mut p = Calibration::PAPER.to_paper_units();
            p[k] = f64::NAN;
            let e = Calibration::from_paper_units(p).check(&m).unwrap_err();
            assert_eq!((e.field, e.kind), (field, IssueKind::NotFinite));
            assert_eq!(
                e.to_string(),
                format!("{} is not a finite number", field.name())
            );
        }
        let mut c = Calibration::PAPER;
        c.c2 = 0.01;
        let e = c.check(&m).unwrap_err();
        assert_eq!(e.field, CalibrationField::C2);
        assert!(e.to_string().contains("must be zero or negative"), "{e}");
        c = Calibration::PAPER;
        c.c6 = 0.0;
        assert_eq!(c.check(&m).unwrap_err().field, CalibrationField::C6);
    }

    #[test]
    fn no_load_current_and_consistency_are_checked() {
        let m = MotorConstants::RS735;
        // A no-load current of 20 A is not this motor's.
        let c = Calibration::from_torque_and_no_load(0.0621, -0.138, 0.00378, 20.0);
        assert_eq!(c.check(&m).unwrap_err().field, CalibrationField::C6);
        let c = Calibration::from_torque_and_no_load(0.0621, -0.138, 0.1, 2.25);
        assert_eq!(c.check(&m).unwrap_err().field, CalibrationField::C5);
        // C3 and C4 against C1 C5 and C1 C6 + C2.
        let mut c = Calibration::PAPER;
        c.c3 *= 1.5;
        let e = c.check(&m).unwrap_err();
        assert_eq!(e.field, CalibrationField::C3);
        assert!(e.to_string().contains("C1 C5 = 0.2347 N mm s/rad"), "{e}");
        let mut c = Calibration::PAPER;
        c.c4 = 10.0e-3;
        let e = c.check(&m).unwrap_err();
        assert_eq!(e.field, CalibrationField::C4);
        assert!(e.to_string().contains("C1 C6 + C2 = 1.725 N mm"), "{e}");
        // Table 2's own 1.69 against 1.725 is within the tolerance, so is a C4 of 2.3.
        c.c4 = 2.3e-3;
        assert_eq!(c.check(&m), Ok(()));
    }

    #[test]
    fn board_limits_cap_the_calibration() {
        let board = BoardLimits::PAPER;
        assert_eq!(board.max_release_load_nm, 3.68);
        assert_eq!(board.max_current_a, 5.0);
        assert_eq!(board.max_freq_hz, 20.0);
        assert_eq!(board.check(&board), Ok(()));
        let mut asked = board;
        asked.max_release_load_nm = 1e30;
        let e = board.check(&asked).unwrap_err();
        assert_eq!(
            (e.field, e.kind),
            (LimitField::MaxReleaseLoad, LimitIssueKind::AboveCap)
        );
        let text = e.to_string();
        assert!(
            text.starts_with("max_release_load_nm = 1.000e30 N m is above"),
            "{text}"
        );
        assert!(text.contains("up to 3.68 N m"), "{text}");
        asked = board;
        asked.max_current_a = f64::NAN;
        let e = board.check(&asked).unwrap_err();
        assert_eq!(
            (e.field, e.kind),
            (LimitField::MaxCurrent, LimitIssueKind::NotFinite)
        );
        asked = board;
        asked.max_freq_hz = 0.0;
        assert_eq!(
            board.check(&asked).unwrap_err().kind,
            LimitIssueKind::NotPositive
        );
        asked.max_freq_hz = 20.5;
        assert_eq!(board.check(&asked).unwrap_err().field, LimitField::MaxFreq);
    }

    #[test]
    fn limits_in_f32_judge_as_in_f64() {
        // The firmware's caps are f32: the f32 check gives the f64 check's verdict on the
        // same numbers widened, at the caps themselves, one f32 step either side, and for
        // NaN, infinities, zero and negatives.
        let caps = [3.68f32, 4.8, 20.0];
        let wide = caps.map(f64::from);
        for (i, &cap) in caps.iter().enumerate() {
            let below = f32::from_bits(cap.to_bits() - 1);
            let above = f32::from_bits(cap.to_bits() + 1);
            let values = [
                cap,
                below,
                above,
                f32::NAN,
                f32::INFINITY,
                f32::NEG_INFINITY,
                0.0,
                -0.0,
                -1.0,
                f32::MIN_POSITIVE,
            ];
            for v in values {
                let mut requested = caps;
                requested[i] = v;
                let narrow = check_limits(requested, caps);
                let double = check_limits(requested.map(f64::from), wide);
                assert_eq!(
                    narrow.map_err(|e| (e.field, e.kind)),
                    double.map_err(|e| (e.field, e.kind)),
                    "limit {i} = {v}"
                );
            }
        }
        let e = check_limits([1.0f32, 9.0, 1.0], caps).unwrap_err();
        assert_eq!(
            (e.field, e.kind, e.value, e.cap),
            (
                LimitField::MaxCurrent,
                LimitIssueKind::AboveCap,
                9.0,
                4.8f32.into()
            )
        );
    }

    #[test]
    fn numbers_print_as_people_write_them() {
        let s = |x: f64| format!("{}", Sig(x));
        assert_eq!(s(0.0621 * 1e3), "62.1");
        assert_eq!(s(1.725), "1.725");
        assert_eq!(s(-138.0), "-138");
        assert_eq!(s(0.00378), "0.00378");
        assert_eq!(s(2258.0), "2258");
        assert_eq!(s(3.4e38), "3.400e38");
    }
}
