//! The service port's protocol: one ASCII line per request, one line per
//! answer, for the bench (the ST-LINK virtual COM port on the board, the
//! `host-sim drive --port` command on the PC). No hardware here: parsing,
//! the answers, and the state they read and change.
//!
//! Requests (case-sensitive, fields separated by single spaces, `\n` ends a
//! line, `\r` before it is ignored, at most [`MAX_LINE`] bytes):
//!
//! | request | answer |
//! |---|---|
//! | `get strategy` | `strategy <off\|table\|adaptive\|learning\|car-observer>` |
//! | `set strategy <name>` | `ok strategy <name>` (installed before the next travel) |
//! | `get mass` | `mass <kg>` (the load weighing's car mass) |
//! | `set mass <kg>` | `ok mass <kg>`; a mass outside (0, 10 000] kg is refused |
//! | `get table` | `table <n> <order> <re N m> <im N m> ...` (numbers in Rust's shortest round-trip form) |
//! | `get faults` | `faults <n> <code> ...` (oldest first, the fault codes of `supervisor::Fault`) |
//! | `get state` | `state <code> speed <rad/s>` (`DriveState::code`) |
//! | `get dcp-mode` | `dcp-mode <dcp3\|dcp4>` (the DCP variant the slave speaks) |
//! | `set dcp-mode <dcp3\|dcp4>` | `ok dcp-mode <name>` (the slave restarts: disabled, position unknown) |
//! | `get params` | `params stored`, `params none` (defaults), `params refused <reason>` or `params unreadable`: what became of the stored record at start-up |
//! | `save` | `ok saved` once the parameters (strategy, the table in use, learned or not, car mass, encoder offset, DCP variant) are written to flash; `error flash-write` if the write failed |
//!
//! Anything else is answered `error <reason>`, never acted on. A `set` or
//! `save` is refused while a travel runs (`error busy`); a drive that cannot
//! install another strategy answers `set strategy` with `error unsupported`,
//! one that cannot write its flash answers `save` so.

use core::fmt::Write;

use crate::dcp::Mode;
use crate::param_store::RecordError;
use crate::ripple::harmonics::HarmonicTable;
use crate::ripple::Strategy;

/// Longest request line, bytes.
pub const MAX_LINE: usize = 64;
/// Longest answer line, bytes (a full table: 8 harmonics).
pub const MAX_ANSWER: usize = 320;
/// Faults the log keeps (the oldest is dropped).
pub const FAULT_LOG: usize = 16;

/// A parsed request.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Request {
    /// `get strategy`.
    GetStrategy,
    /// `set strategy <name>`.
    SetStrategy(Strategy),
    /// `get mass`.
    GetMass,
    /// `set mass <kg>`.
    SetMass(f32),
    /// `get table`.
    GetTable,
    /// `get faults`.
    GetFaults,
    /// `get state`.
    GetState,
    /// `get dcp-mode`.
    GetDcpMode,
    /// `set dcp-mode <dcp3|dcp4>`.
    SetDcpMode(Mode),
    /// `get params`.
    GetParams,
    /// `save`.
    Save,
    /// `reset`: clear latched faults (the drive's own answer says whether
    /// one was latched).
    Reset,
    /// `align`: run the rotor alignment (brake open, current injected), on
    /// a drive that needs one.
    Align,
}

/// The name of a DCP variant on the service port.
pub fn mode_name(mode: Mode) -> &'static str {
    match mode {
        Mode::Dcp3 => "dcp3",
        Mode::Dcp4 => "dcp4",
    }
}

/// What became of the stored parameter record at start-up.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ParamsStatus {
    /// None stored: the drive runs with its defaults.
    None,
    /// A record passed every check and is in use.
    Stored,
    /// A record was refused (the drive runs with its defaults).
    Refused(RecordError),
    /// The store could not be read (the drive runs with its defaults).
    Unreadable,
}

/// The reason word of a refused record.
pub fn record_error_word(e: RecordError) -> &'static str {
    match e {
        RecordError::Truncated => "truncated",
        RecordError::Magic => "magic",
        RecordError::Version(_) => "version",
        RecordError::Crc => "crc",
        RecordError::Content => "content",
    }
}

/// Why a request line is refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RequestError {
    /// Longer than [`MAX_LINE`] or not ASCII.
    Line,
    /// Not a request of the table.
    Unknown,
    /// A strategy name that does not exist.
    Strategy,
    /// A mass that is not a number in (0, 10 000] kg.
    Mass,
    /// A `set` while a travel runs.
    Busy,
    /// A request this drive does not carry out (see
    /// [`ServiceState::strategy_settable`], [`ServiceState::savable`]).
    Unsupported,
    /// A DCP variant that does not exist.
    DcpMode,
}

impl RequestError {
    /// The reason word of the `error` answer.
    pub fn word(self) -> &'static str {
        match self {
            RequestError::Line => "line",
            RequestError::Unknown => "unknown-request",
            RequestError::Strategy => "unknown-strategy",
            RequestError::Mass => "mass-out-of-range",
            RequestError::Busy => "busy",
            RequestError::Unsupported => "unsupported",
            RequestError::DcpMode => "unknown-dcp-mode",
        }
    }
}

/// The request of one line (without its `\n`).
pub fn parse(line: &[u8]) -> Result<Request, RequestError> {
    let line = line.strip_suffix(b"\r").unwrap_or(line);
    if line.len() > MAX_LINE || !line.is_ascii() {
        return Err(RequestError::Line);
    }
    let text = core::str::from_utf8(line).map_err(|_| RequestError::Line)?;
    let mut words = text.split(' ');
    let request = match (words.next(), words.next(), words.next()) {
        (Some("get"), Some("strategy"), None) => Request::GetStrategy,
        (Some("get"), Some("mass"), None) => Request::GetMass,
        (Some("get"), Some("table"), None) => Request::GetTable,
        (Some("get"), Some("faults"), None) => Request::GetFaults,
        (Some("get"), Some("state"), None) => Request::GetState,
        (Some("get"), Some("dcp-mode"), None) => Request::GetDcpMode,
        (Some("get"), Some("params"), None) => Request::GetParams,
        (Some("save"), None, None) => Request::Save,
        (Some("reset"), None, None) => Request::Reset,
        (Some("align"), None, None) => Request::Align,
        (Some("set"), Some("dcp-mode"), Some(name)) => Request::SetDcpMode(match name {
            "dcp3" => Mode::Dcp3,
            "dcp4" => Mode::Dcp4,
            _ => return Err(RequestError::DcpMode),
        }),
        (Some("set"), Some("strategy"), Some(name)) => Request::SetStrategy(
            Strategy::ALL.iter().copied().find(|s| s.name() == name).ok_or(RequestError::Strategy)?,
        ),
        (Some("set"), Some("mass"), Some(kg)) => {
            let kg: f32 = kg.parse().map_err(|_| RequestError::Mass)?;
            if !(kg > 0.0 && kg <= 10_000.0) {
                return Err(RequestError::Mass);
            }
            Request::SetMass(kg)
        }
        _ => return Err(RequestError::Unknown),
    };
    if words.next().is_some() {
        return Err(RequestError::Unknown);
    }
    Ok(request)
}

/// What the service port reads and changes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ServiceState {
    /// The strategy to install before the next travel.
    pub strategy: Strategy,
    /// The harmonic table in use, N m.
    pub table: HarmonicTable,
    /// Car mass of the load weighing, kg.
    pub m_car_kg: f32,
    /// Fault codes, oldest first (the first `fault_count`).
    pub faults: [u8; FAULT_LOG],
    /// Faults held.
    pub fault_count: usize,
    /// `DriveState::code` of the drive now.
    pub state_code: u8,
    /// Shaft speed now, rad/s.
    pub speed_radps: f32,
    /// A travel runs (sets are refused).
    pub travelling: bool,
    /// Whether `set strategy` is carried out (false: answered `error unsupported`).
    pub strategy_settable: bool,
    /// The DCP variant the slave speaks.
    pub dcp_mode: Mode,
    /// What became of the stored record at start-up.
    pub params: ParamsStatus,
    /// Whether `save` is carried out (false: answered `error unsupported`).
    pub savable: bool,
    /// Set by a valid `save`: the caller writes the record, then clears it
    /// (and answers `error flash-write` instead if the write fails).
    pub save_requested: bool,
}

impl ServiceState {
    /// Appends a fault code to the log, dropping the oldest when full.
    pub fn log_fault(&mut self, code: u8) {
        if self.fault_count == FAULT_LOG {
            self.faults.copy_within(1.., 0);
            self.fault_count -= 1;
        }
        self.faults[self.fault_count] = code;
        self.fault_count += 1;
    }
}

/// An answer line (without `\n`).
pub struct Answer {
    bytes: [u8; MAX_ANSWER],
    len: usize,
}

impl Answer {
    fn new() -> Self {
        Self { bytes: [0; MAX_ANSWER], len: 0 }
    }

    /// The answer's bytes.
    pub fn as_bytes(&self) -> &[u8] {
        &self.bytes[..self.len]
    }
}

impl Write for Answer {
    fn write_str(&mut self, s: &str) -> core::fmt::Result {
        let end = self.len + s.len();
        if end > MAX_ANSWER {
            return Err(core::fmt::Error);
        }
        self.bytes[self.len..end].copy_from_slice(s.as_bytes());
        self.len = end;
        Ok(())
    }
}

/// What a request line is answered, before it is written as text: the
/// values it reads are copied in, so that the (costly) formatting can run
/// apart from the state, in another task ([`Response::write`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Response {
    /// `error <word>`.
    Error(&'static str),
    /// `strategy <name>`.
    Strategy(Strategy),
    /// `ok strategy <name>`.
    StrategySet(Strategy),
    /// `mass <kg>`.
    Mass(f32),
    /// `ok mass <kg>`.
    MassSet(f32),
    /// `table <n> <order> <re N m> <im N m> ...`.
    Table(HarmonicTable),
    /// `faults <n> <code> ...`: the codes, oldest first (the first `n`).
    Faults([u8; FAULT_LOG], usize),
    /// `state <code> speed <rad/s>`.
    State(u8, f32),
    /// `dcp-mode <name>`.
    DcpMode(Mode),
    /// `ok dcp-mode <name>`.
    DcpModeSet(Mode),
    /// `params ...`.
    Params(ParamsStatus),
    /// `ok saved`.
    Saved,
    /// `ok reset`.
    Reset,
    /// `ok align`.
    Align,
}

impl Response {
    /// The answer line (without `\n`).
    pub fn write(&self) -> Answer {
        let mut out = Answer::new();
        // Every answer fits MAX_ANSWER (numbers in Rust's shortest round-trip
        // form, a full table at most 8 x 38 bytes): the writes cannot fail.
        let _ = match self {
            Response::Error(word) => write!(out, "error {word}"),
            Response::Strategy(s) => write!(out, "strategy {}", s.name()),
            Response::StrategySet(s) => write!(out, "ok strategy {}", s.name()),
            Response::Mass(kg) => write!(out, "mass {kg:?}"),
            Response::MassSet(kg) => write!(out, "ok mass {kg:?}"),
            Response::Table(t) => {
                let n = t.len.min(t.orders.len());
                let _ = write!(out, "table {n}");
                (0..n).try_for_each(|k| write!(out, " {} {:?} {:?}", t.orders[k], t.torque_nm[k].re, t.torque_nm[k].im))
            }
            Response::Faults(codes, n) => {
                let n = (*n).min(FAULT_LOG);
                let _ = write!(out, "faults {n}");
                codes[..n].iter().try_for_each(|c| write!(out, " {c}"))
            }
            Response::State(code, speed) => write!(out, "state {code} speed {speed:?}"),
            Response::DcpMode(mode) => write!(out, "dcp-mode {}", mode_name(*mode)),
            Response::DcpModeSet(mode) => write!(out, "ok dcp-mode {}", mode_name(*mode)),
            Response::Params(status) => match status {
                ParamsStatus::None => write!(out, "params none"),
                ParamsStatus::Stored => write!(out, "params stored"),
                ParamsStatus::Refused(e) => write!(out, "params refused {}", record_error_word(*e)),
                ParamsStatus::Unreadable => write!(out, "params unreadable"),
            },
            Response::Saved => write!(out, "ok saved"),
            Response::Reset => write!(out, "ok reset"),
            Response::Align => write!(out, "ok align"),
        };
        out
    }

    /// Whether the request was taken (not an `error` answer).
    pub fn is_ok(&self) -> bool {
        !matches!(self, Response::Error(_))
    }
}

/// The response to one request line, changing `state` for a valid `set`
/// (no formatting: see [`Response::write`]).
pub fn respond(line: &[u8], state: &mut ServiceState) -> Response {
    let result = parse(line).and_then(|request| {
        let is_set = matches!(
            request,
            Request::SetStrategy(_) | Request::SetMass(_) | Request::SetDcpMode(_) | Request::Save | Request::Align
        );
        if is_set && state.travelling {
            Err(RequestError::Busy)
        } else if (matches!(request, Request::SetStrategy(_)) && !state.strategy_settable)
            || (request == Request::Save && !state.savable)
        {
            Err(RequestError::Unsupported)
        } else {
            Ok(request)
        }
    });
    match result {
        Err(e) => Response::Error(e.word()),
        Ok(Request::GetStrategy) => Response::Strategy(state.strategy),
        Ok(Request::SetStrategy(s)) => {
            state.strategy = s;
            Response::StrategySet(s)
        }
        Ok(Request::GetMass) => Response::Mass(state.m_car_kg),
        Ok(Request::SetMass(kg)) => {
            state.m_car_kg = kg;
            Response::MassSet(kg)
        }
        Ok(Request::GetTable) => Response::Table(state.table),
        Ok(Request::GetFaults) => Response::Faults(state.faults, state.fault_count),
        Ok(Request::GetState) => Response::State(state.state_code, state.speed_radps),
        Ok(Request::GetDcpMode) => Response::DcpMode(state.dcp_mode),
        Ok(Request::SetDcpMode(mode)) => {
            state.dcp_mode = mode;
            Response::DcpModeSet(mode)
        }
        Ok(Request::GetParams) => Response::Params(state.params),
        Ok(Request::Save) => {
            state.save_requested = true;
            Response::Saved
        }
        // Carried out by the caller, which answers `error nothing-to-reset`
        // (or `error busy`, `error unsupported` for `align`) instead when it
        // does not apply.
        Ok(Request::Reset) => Response::Reset,
        Ok(Request::Align) => Response::Align,
    }
}

/// Answers one request line, changing `state` for a valid `set`
/// ([`respond`], then [`Response::write`]).
pub fn answer(line: &[u8], state: &mut ServiceState) -> Answer {
    respond(line, state).write()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ripple::complex::Complex;

    fn state() -> ServiceState {
        let mut table = HarmonicTable::zero(&[1, 12]);
        table.torque_nm[1] = Complex::new(-3.5, 0.25);
        ServiceState {
            strategy: Strategy::Table,
            table,
            m_car_kg: 70.5,
            faults: [0; FAULT_LOG],
            fault_count: 0,
            state_code: 0,
            speed_radps: 0.0,
            travelling: false,
            strategy_settable: true,
            dcp_mode: Mode::Dcp4,
            params: ParamsStatus::Refused(RecordError::Crc),
            savable: true,
            save_requested: false,
        }
    }

    fn ask(line: &str, s: &mut ServiceState) -> std::string::String {
        std::string::String::from_utf8(answer(line.as_bytes(), s).as_bytes().to_vec()).unwrap()
    }

    extern crate std;

    #[test]
    fn every_request_of_the_table_is_answered() {
        let mut s = state();
        assert_eq!(ask("get strategy", &mut s), "strategy table");
        assert_eq!(ask("set strategy car-observer\r", &mut s), "ok strategy car-observer");
        assert_eq!(s.strategy, Strategy::CarObserver);
        assert_eq!(ask("get mass", &mut s), "mass 70.5");
        assert_eq!(ask("set mass 45.5", &mut s), "ok mass 45.5");
        assert_eq!(s.m_car_kg, 45.5);
        assert_eq!(ask("get table", &mut s), "table 2 1 0.0 0.0 12 -3.5 0.25");
        s.log_fault(1);
        s.log_fault(7);
        assert_eq!(ask("get faults", &mut s), "faults 2 1 7");
        s.state_code = 3;
        s.speed_radps = 6.125;
        assert_eq!(ask("get state", &mut s), "state 3 speed 6.125");
        assert_eq!(ask("get dcp-mode", &mut s), "dcp-mode dcp4");
        assert_eq!(ask("set dcp-mode dcp3", &mut s), "ok dcp-mode dcp3");
        assert_eq!(s.dcp_mode, Mode::Dcp3);
        assert_eq!(ask("get params", &mut s), "params refused crc");
        assert!(!s.save_requested);
        assert_eq!(ask("save", &mut s), "ok saved");
        assert!(s.save_requested);
    }

    #[test]
    fn bad_requests_are_refused_and_change_nothing() {
        let mut s = state();
        let before = s;
        for (line, word) in [
            ("get", "unknown-request"),
            ("get strategy now", "unknown-request"),
            ("set strategy fast", "unknown-strategy"),
            ("set mass -3", "mass-out-of-range"),
            ("set mass NaN", "mass-out-of-range"),
            ("set mass 1e9", "mass-out-of-range"),
            ("set  mass 3", "unknown-request"),
            ("gét state", "line"),
            ("set dcp-mode dcp5", "unknown-dcp-mode"),
            ("save now", "unknown-request"),
        ] {
            assert_eq!(ask(line, &mut s), std::format!("error {word}"), "{line}");
        }
        let long = [b'a'; MAX_LINE + 1];
        assert_eq!(answer(&long, &mut s).as_bytes(), b"error line");
        s.travelling = true;
        assert_eq!(ask("set mass 50", &mut s), "error busy");
        assert_eq!(ask("set dcp-mode dcp3", &mut s), "error busy");
        assert_eq!(ask("save", &mut s), "error busy");
        s.travelling = false;
        s.savable = false;
        assert_eq!(ask("save", &mut s), "error unsupported");
        s.savable = true;
        s.strategy_settable = false;
        assert_eq!(ask("set strategy off", &mut s), "error unsupported");
        s.strategy_settable = true;
        assert_eq!(s, before);
    }

    #[test]
    fn reset_and_align_are_requests_the_caller_carries_out() {
        let mut s = state();
        assert_eq!(parse(b"reset"), Ok(Request::Reset));
        assert_eq!(parse(b"align"), Ok(Request::Align));
        assert_eq!(parse(b"reset now"), Err(RequestError::Unknown));
        assert_eq!(ask("reset", &mut s), "ok reset");
        assert_eq!(ask("align", &mut s), "ok align");
        // No alignment during a travel.
        s.travelling = true;
        assert_eq!(ask("align", &mut s), "error busy");
    }

    #[test]
    fn the_fault_log_keeps_the_newest() {
        let mut s = state();
        for code in 0..(FAULT_LOG as u8 + 3) {
            s.log_fault(code);
        }
        assert_eq!(s.fault_count, FAULT_LOG);
        assert_eq!(s.faults[0], 3);
        assert_eq!(s.faults[FAULT_LOG - 1], FAULT_LOG as u8 + 2);
    }

    #[test]
    fn a_full_table_fits_the_answer() {
        let mut s = state();
        s.table = HarmonicTable::zero(&[65535; 8]);
        for u in s.table.torque_nm.iter_mut() {
            *u = Complex::new(-1.234_567_9e-30, -9.876_543e30);
        }
        let a = ask("get table", &mut s);
        assert!(a.starts_with("table 8 65535 "), "{a}");
        assert_eq!(a.split(' ').count(), 2 + 8 * 3, "{a}");
    }
}
