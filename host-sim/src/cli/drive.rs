//! `host-sim drive --port PORT REQUEST...`: one request of the service
//! port's line protocol (`drive_core::service`) to a drive on a serial port
//! (the NUCLEO's ST-LINK virtual COM port, e.g. `/dev/ttyACM0`), and its
//! answer on standard output; `--every-ms` repeats it (a crude telemetry
//! stream of `get state`).
//!
//! ```text
//! host-sim drive --port /dev/ttyACM0 get state
//! host-sim drive --port /dev/ttyACM0 set mass 58
//! host-sim drive --port /dev/ttyACM0 --every-ms 100 --count 50 get state
//! ```
//!
//! The request is checked here with the drive's own parser before it is
//! sent, so a mistyped request never reaches the drive; an `error ...`
//! answer of the drive makes the command fail with that answer.

use std::time::{Duration, Instant};

use anyhow::{bail, Context};
use clap::Args;

use rig_config::RigConfig;

/// Arguments of `host-sim drive`.
#[derive(Debug, Args)]
pub struct DriveArgs {
    /// Serial port of the drive's service port (e.g. /dev/ttyACM0).
    #[arg(long, value_name = "PORT")]
    pub port: String,
    /// Baud rate of the service port.
    #[arg(long, default_value_t = 115_200)]
    pub baud: u32,
    /// Longest wait for an answer, ms.
    #[arg(long = "timeout-ms", default_value_t = 1000)]
    pub timeout_ms: u64,
    /// Repeat the request every this many ms (0: once).
    #[arg(long = "every-ms", default_value_t = 0)]
    pub every_ms: u64,
    /// Repetitions with `--every-ms`.
    #[arg(long, default_value_t = 10)]
    pub count: u32,
    /// The request, e.g. `get state`, `set mass 58`, `get table`.
    #[arg(required = true, num_args = 1..)]
    pub request: Vec<String>,
}

/// Sends `line` (without its newline) and returns the answer line.
pub fn exchange(port: &mut dyn serialport::SerialPort, line: &str, timeout: Duration) -> anyhow::Result<String> {
    port.write_all(format!("{line}\n").as_bytes()).context("writing to the serial port")?;
    port.flush().context("writing to the serial port")?;
    let started = Instant::now();
    let mut answer = Vec::new();
    let mut byte = [0u8; 1];
    loop {
        if started.elapsed() > timeout {
            bail!("no answer from the drive within {} ms", timeout.as_millis());
        }
        match port.read(&mut byte) {
            Ok(0) => continue,
            Ok(_) if byte[0] == b'\n' => break,
            Ok(_) => {
                answer.push(byte[0]);
                if answer.len() > drive_core::service::MAX_ANSWER + 1 {
                    bail!(
                        "answer longer than {} bytes: not the drive's service port?",
                        drive_core::service::MAX_ANSWER
                    );
                }
            }
            Err(e) if e.kind() == std::io::ErrorKind::TimedOut => continue,
            Err(e) => return Err(e).context("reading from the serial port"),
        }
    }
    let text = String::from_utf8(answer).context("the answer is not text: not the drive's service port?")?;
    let text = text.strip_suffix('\r').unwrap_or(&text).to_string();
    Ok(text)
}

/// Checks the request with the drive's parser.
pub fn request_line(words: &[String]) -> anyhow::Result<String> {
    let line = words.join(" ");
    if let Err(e) = drive_core::service::parse(line.as_bytes()) {
        bail!(
            "`{line}` is not a service request ({}): expected get strategy|mass|table|faults|state, \
             set strategy <off|table|adaptive|learning|car-observer>, set mass <kg>",
            e.word()
        );
    }
    Ok(line)
}

/// Refuses an answer that cannot be the drive's to `line`: the request
/// itself (a line that echoes: a loopback, a terminal with echo on, not the
/// drive), and to a `set` anything but `ok ...` or `error ...` (a setting
/// must never be reported as confirmed unless the drive said so).
pub fn check_answer(line: &str, answer: &str) -> anyhow::Result<()> {
    if answer.trim() == line.trim() {
        bail!(
            "the answer to `{line}` is the request itself: the line echoes what it is sent (a loopback, a terminal \
             with echo on, or not the drive's service port); expected the drive's answer"
        );
    }
    if line.starts_with("set ") && !(answer.starts_with("ok ") || answer.starts_with("error")) {
        bail!("the answer to `{line}` is `{answer}`: expected `ok ...` or `error ...` from the drive's service port");
    }
    Ok(())
}

/// Runs `host-sim drive`.
pub fn run(_rig: &RigConfig, args: &DriveArgs) -> anyhow::Result<()> {
    let line = request_line(&args.request)?;
    let timeout = Duration::from_millis(args.timeout_ms);
    let mut port = serialport::new(&args.port, args.baud)
        .timeout(Duration::from_millis(20))
        .open()
        .with_context(|| format!("cannot open the serial port {}", args.port))?;
    let repeats = if args.every_ms == 0 { 1 } else { args.count.max(1) };
    for i in 0..repeats {
        if i > 0 {
            std::thread::sleep(Duration::from_millis(args.every_ms));
        }
        let answer = exchange(port.as_mut(), &line, timeout).with_context(|| format!("on {}", args.port))?;
        check_answer(&line, &answer).with_context(|| format!("on {}", args.port))?;
        if answer.starts_with("error") {
            bail!("the drive refused `{line}`: {answer}");
        }
        outln!("{answer}");
    }
    Ok(())
}

#[cfg(all(test, unix))]
mod tests {
    use super::*;
    use drive_core::ripple::harmonics::HarmonicTable;
    use drive_core::ripple::Strategy;
    use drive_core::service::{answer, ServiceState, FAULT_LOG};
    use serialport::{SerialPort, TTYPort};
    use std::io::{Read, Write};

    /// A drive double on the other end of a pseudo-terminal, answering
    /// with the drive's own protocol code.
    /// Gives its end of the line back with its state, so that the line
    /// stays open until the test has read every answer.
    fn drive_double(mut port: TTYPort, requests: usize) -> std::thread::JoinHandle<(ServiceState, TTYPort)> {
        std::thread::spawn(move || {
            let mut state = ServiceState {
                strategy: Strategy::Table,
                table: HarmonicTable::zero(&[12]),
                m_car_kg: 70.5,
                faults: [0; FAULT_LOG],
                fault_count: 0,
                state_code: 0,
                speed_radps: 0.0,
                travelling: false,
                strategy_settable: true,
                dcp_mode: drive_core::dcp::Mode::Dcp4,
                params: drive_core::service::ParamsStatus::None,
                savable: false,
                save_requested: false,
            };
            let mut line = Vec::new();
            let mut served = 0;
            let mut byte = [0u8; 1];
            while served < requests {
                match port.read(&mut byte) {
                    Ok(1) if byte[0] == b'\n' => {
                        let a = answer(&line, &mut state);
                        port.write_all(a.as_bytes()).unwrap();
                        port.write_all(b"\r\n").unwrap();
                        line.clear();
                        served += 1;
                    }
                    Ok(1) => line.push(byte[0]),
                    _ => {}
                }
            }
            (state, port)
        })
    }

    #[test]
    fn a_request_over_a_serial_line_gets_the_drives_answer() {
        let (mut host, drive) = TTYPort::pair().expect("a pseudo-terminal pair");
        host.set_timeout(Duration::from_millis(20)).unwrap();
        let double = drive_double(drive, 3);
        let t = Duration::from_secs(2);
        assert_eq!(exchange(&mut host, "get mass", t).unwrap(), "mass 70.5");
        assert_eq!(exchange(&mut host, "set mass 58", t).unwrap(), "ok mass 58.0");
        assert_eq!(exchange(&mut host, "set strategy fast", t).unwrap(), "error unknown-strategy");
        let (state, _line) = double.join().unwrap();
        assert_eq!(state.m_car_kg, 58.0);
    }

    #[test]
    fn a_line_that_echoes_is_not_taken_for_the_drive() {
        let (mut host, mut echo) = TTYPort::pair().expect("a pseudo-terminal pair");
        host.set_timeout(Duration::from_millis(20)).unwrap();
        let echoing = std::thread::spawn(move || {
            let mut line = Vec::new();
            let mut byte = [0u8; 1];
            loop {
                if let Ok(1) = echo.read(&mut byte) {
                    line.push(byte[0]);
                    if byte[0] == b'\n' {
                        echo.write_all(&line).unwrap();
                        return echo;
                    }
                }
            }
        });
        let answer = exchange(&mut host, "set mass 58", Duration::from_secs(2)).unwrap();
        let _line = echoing.join().unwrap();
        let e = check_answer("set mass 58", &answer).unwrap_err().to_string();
        assert!(e.contains("echoes"), "{e}");
        // A `set` answered by anything but ok/error is not a confirmation.
        assert!(check_answer("set mass 58", "mass 70.5").is_err());
        check_answer("set mass 58", "ok mass 58.0").unwrap();
        check_answer("get mass", "mass 70.5").unwrap();
    }

    #[test]
    fn a_silent_port_times_out_with_a_clear_error() {
        let (mut host, _drive) = TTYPort::pair().expect("a pseudo-terminal pair");
        host.set_timeout(Duration::from_millis(10)).unwrap();
        let e = exchange(&mut host, "get state", Duration::from_millis(100)).unwrap_err();
        assert_eq!(e.to_string(), "no answer from the drive within 100 ms");
    }

    #[test]
    fn a_mistyped_request_is_refused_before_it_is_sent() {
        let words = |s: &str| s.split(' ').map(String::from).collect::<Vec<_>>();
        assert_eq!(request_line(&words("get state")).unwrap(), "get state");
        let e = request_line(&words("set mass heavy")).unwrap_err().to_string();
        assert!(e.starts_with("`set mass heavy` is not a service request (mass-out-of-range)"), "{e}");
    }
}
