//! Processor in the loop with a lift controller on the DCP line: the
//! emulated chip (QEMU mps2-an386) runs the drive's application layer
//! (`drive_core::lift_drive::LiftDrive`: service port, DCP slave, the
//! commands it gives, the controller) with the PIL frames on UART0, the DCP
//! line on UART1 and the service port on UART2; this side plays the lift
//! controller and closes the loop around the plant. A host build of the
//! same application layer (the shadow) takes the DCP and service bytes the
//! chip reports it took at each step, and every step's outputs, telemetry
//! digest, DCP replies and service answers must be equal bit for bit. The
//! harness is `closed_loop::pil::dcp` (also behind `host-sim pil --dcp`).
//!
//! Needs `qemu-system-arm` and the PIL ELF (`scripts/test.sh` builds both;
//! `PIL_ELF` overrides the path).

use std::path::Path;
use std::time::Instant;

use closed_loop::pil::dcp::{
    default_elf, default_parameters, geometry, Chip, CpuLoad, Lift, Master, Phase, Trip, CYCLE_STEPS,
};
use drive_core::dcp::channel::position_message;
use drive_core::dcp::command::{command_byte, Kind, Mode, Speed};
use drive_core::dcp::slave::{S1_TRAVEL, S5_ACCEPTED, S7_MESSAGE_ERROR};
use drive_core::dcp::{MasterFrame, SlaveFrame};
use drive_core::lift_drive::LiftDrive;
use drive_core::service::ParamsStatus;
use drive_core::DriveState;
use rig_config::RigConfig;

fn rig() -> RigConfig {
    RigConfig::embedded_default().expect("the embedded rig loads")
}

/// A chip started in `dir` with the lift's car at `lw_start_m` (the heaviest car).
fn lift_in(dir: &Path, lw_start_m: f64) -> Lift {
    let rig = rig();
    let chip = Chip::launch(&default_elf(), Path::new("qemu-system-arm"), dir).expect("the PIL target starts");
    let m_car = geometry(&rig).1 as f64;
    Lift::new(&rig, Some(chip), &default_parameters(&rig), ParamsStatus::None, m_car, lw_start_m).expect("a lift")
}

/// Everything a run gives back.
struct Run {
    steps: u64,
    states: Vec<DriveState>,
    brake_released: Vec<bool>,
    ref_speed_mps: Vec<f32>,
    /// The chip's controller step, instructions.
    instructions: Vec<f64>,
    shadow: LiftDrive,
}

/// Runs the chip and the shadow closed around the plant for at most
/// `max_steps`, until `done` says so; `master` decides the DCP bytes and
/// `service` the service-port bytes of each step.
fn run_loop(
    master: &mut dyn FnMut(u64, f64) -> Vec<u8>,
    on_replies: &mut dyn FnMut(&[u8]),
    done: &mut dyn FnMut(u64, &DriveState) -> bool,
    max_steps: u64,
    lw_start_m: f64,
) -> Run {
    let dir = tempfile::tempdir().unwrap();
    let mut lift = lift_in(dir.path(), lw_start_m);
    run_lift(&mut lift, master, &mut |_| Vec::new(), on_replies, done, max_steps)
}

fn run_lift(
    lift: &mut Lift,
    master: &mut dyn FnMut(u64, f64) -> Vec<u8>,
    service: &mut dyn FnMut(u64) -> Vec<u8>,
    on_replies: &mut dyn FnMut(&[u8]),
    done: &mut dyn FnMut(u64, &DriveState) -> bool,
    max_steps: u64,
) -> Run {
    let mut states = Vec::new();
    let mut brake_released = Vec::new();
    let mut ref_speed_mps = Vec::new();
    let mut instructions = Vec::new();
    let started = Instant::now();
    let mut k = 0;
    while k < max_steps {
        let out = master(k, lift.position_mm());
        let step = lift.step(&out, &service(k)).unwrap_or_else(|e| panic!("{e:#}"));
        on_replies(&step.dcp_replies);
        states.push(step.output.state);
        brake_released.push(step.output.brake_released);
        ref_speed_mps.push(step.output.telemetry.ref_speed_mps);
        instructions.push(step.instructions.unwrap_or(0.0));
        k += 1;
        if done(k, &step.output.state) {
            break;
        }
    }
    println!("{k} DCP PIL steps in {:.1} s", started.elapsed().as_secs_f64());
    Run { steps: k, states, brake_released, ref_speed_mps, instructions, shadow: *lift.shadow() }
}

fn master(mode: Mode, targets: &[i32]) -> Master {
    let trips = targets.iter().map(|&target_mm| Trip { target_mm, speed: Speed::V4 }).collect();
    Master::new(mode, trips, &rig().drive_config())
}

#[test]
fn dcp4_travels_between_landings_on_the_emulated_chip_are_bit_identical_to_the_host() {
    let rig = rig();
    let (geometry, _) = geometry(&rig);
    // Car at 1000 mm above the lowest landing; up 600 mm, then down 300 mm.
    let lw_start = geometry.lw_lowest_landing_m as f64 + 1.0;
    let master = std::cell::RefCell::new(master(Mode::Dcp4, &[1600, 1300]));
    let run = run_loop(
        &mut |k, position| master.borrow_mut().bytes(k, position),
        &mut |replies| master.borrow_mut().receive(replies).unwrap(),
        &mut |_, _| master.borrow().phase() == Phase::Done,
        200_000,
        lw_start,
    );
    let master = master.into_inner();
    assert_eq!(master.phase(), Phase::Done, "the sequence did not finish in {} steps", run.steps);
    assert_eq!(master.arrivals.len(), 2);
    for (arrival, target) in master.arrivals.iter().zip([1600.0, 1300.0]) {
        let position = arrival.position_mm;
        println!("landed at {position:.2} mm, target {target} mm");
        assert!((position - target).abs() < 3.0, "landed at {position:.1} mm, target {target} mm");
    }
    assert!(master.replies.iter().all(|r| r.status & S7_MESSAGE_ERROR == 0), "a good message got the error bit");
    assert_eq!(run.shadow.port().slave().position_mm(), Some(1300));
    let travelled = run.states.iter().filter(|s| **s == DriveState::Travel).count();
    assert!(travelled > 16_000, "{travelled} steps in Travel");
}

#[test]
fn a_dcp4_travel_follows_a_remaining_distance_changed_by_rope_slip_bit_identical_to_the_host() {
    let rig = rig();
    let (geometry, _) = geometry(&rig);
    // From 1000 mm up to 2200 mm, then down to 1300 mm. The lift controller
    // measures the car on its own shaft encoder: 1 s into the first travel
    // the ropes slip 30 mm (the car ahead of the sheave: the remaining
    // distance shortens), 1 s into the second 50 mm more (the car above
    // the sheave's count going down: the remaining distance lengthens).
    let lw_start = geometry.lw_lowest_landing_m as f64 + 1.0;
    let master = std::cell::RefCell::new(master(Mode::Dcp4, &[2200, 1300]));
    // (Travels begun, steps in the latest travel.)
    let travel = std::cell::Cell::new((0u32, 0u64));
    // The car's position on the lift controller's encoder less the plant's, mm.
    let slip_mm = std::cell::Cell::new(0.0f64);
    let run = run_loop(
        &mut |k, position| master.borrow_mut().bytes(k, position + slip_mm.get()),
        &mut |replies| master.borrow_mut().receive(replies).unwrap(),
        &mut |_, state| {
            let (begun, steps) = travel.get();
            travel.set(match (*state == DriveState::Travel, steps) {
                (true, 0) => (begun + 1, 1),
                (true, n) => (begun, n + 1),
                (false, _) => (begun, 0),
            });
            // 1 s into each travel, the slip of that travel.
            match travel.get() {
                (1, 16_000) => slip_mm.set(30.0),
                (2, 16_000) => slip_mm.set(80.0),
                _ => {}
            }
            master.borrow().phase() == Phase::Done
        },
        250_000,
        lw_start,
    );
    let master = master.into_inner();
    assert_eq!(master.phase(), Phase::Done, "the sequence did not finish in {} steps", run.steps);
    assert_eq!(master.arrivals.len(), 2);
    let (begun, last_steps) = travel.get();
    assert_eq!(begun, 2);
    assert_eq!(last_steps, 0);
    assert_eq!(slip_mm.get(), 80.0, "both slips happened");
    let travelled = run.states.iter().filter(|s| **s == DriveState::Travel).count();
    assert!(travelled > 2 * 16_000, "{travelled} steps in Travel");
    // Within 5 mm (half the +-10 mm stopping accuracy of EN 81-20): the
    // plan made at the slip takes the ropes' stretch of that instant along.
    for (arrival, target) in master.arrivals.iter().zip([2200.0, 1300.0]) {
        let position = arrival.position_mm;
        println!("landed at {position:.2} mm on the lift controller's encoder, target {target} mm");
        assert!((position - target).abs() < 5.0, "landed at {position:.1} mm, target {target} mm");
    }
    assert!(master.replies.iter().all(|r| r.status & S7_MESSAGE_ERROR == 0), "a good message got the error bit");
    assert!(
        master.replies.iter().all(|r| r.status & S1_TRAVEL == 0 || r.status & S5_ACCEPTED != 0),
        "a remaining distance refused"
    );
    assert_within_limits(&run.ref_speed_mps, &rig);
}

/// Acceleration and jerk of the speed reference within the rig's limits
/// (differences over 4 ms of steps).
fn assert_within_limits(ref_speed_mps: &[f32], rig: &RigConfig) {
    let drive = rig.drive_config();
    let n = 64;
    let dt = n as f64 / drive.current_loop_hz as f64;
    let v: Vec<f64> = ref_speed_mps.iter().map(|&v| v as f64).collect();
    let a: Vec<f64> = (n..v.len()).map(|i| (v[i] - v[i - n]) / dt).collect();
    for i in n..a.len() {
        assert!(a[i].abs() <= drive.max_accel_mps2 as f64 * 1.001, "acceleration {} at step {i}", a[i]);
        let jerk = (a[i] - a[i - n]) / dt;
        assert!(jerk.abs() <= drive.max_jerk_mps3 as f64 * 1.02, "jerk {jerk} at step {i}");
    }
}

#[test]
fn a_silent_master_mid_travel_stops_the_drive_within_the_timeout_with_the_brake_applied() {
    let rig = rig();
    let (geometry, _) = geometry(&rig);
    let lw_start = geometry.lw_lowest_landing_m as f64 + 1.0;
    let master = std::cell::RefCell::new(master(Mode::Dcp4, &[3000]));
    let mut travel_since = None;
    let run = run_loop(
        &mut |k, position| {
            let mut m = master.borrow_mut();
            m.bytes(k, position)
        },
        &mut |replies| master.borrow_mut().receive(replies).unwrap(),
        &mut |k, state| {
            // Silent after 0.5 s of travel; stop the run 0.2 s after that.
            if *state == DriveState::Travel && travel_since.is_none() {
                travel_since = Some(k);
            }
            match travel_since {
                Some(t) if k == t + 8_000 => {
                    master.borrow_mut().silent_from = Some(k);
                    false
                }
                Some(t) => k >= t + 8_000 + 3_200,
                None => false,
            }
        },
        200_000,
        lw_start,
    );
    let master = master.into_inner();
    let last = master.last_sent as usize;
    let stopped = (last..run.steps as usize)
        .find(|&k| run.states[k] == DriveState::Idle)
        .expect("the drive stopped after the master fell silent");
    assert!(run.states[..last].contains(&DriveState::Travel));
    assert!(!run.brake_released[stopped], "brake applied at the stop");
    assert!(run.states[stopped..].iter().all(|s| *s == DriveState::Idle), "stays stopped");
    let ts_ms = 1000.0 / rig.control.current_loop_hz;
    let delay_ms = (stopped - last) as f64 * ts_ms;
    // The watchdog runs from the end of the last message: 6 bytes and the
    // idle gap after its first byte, then 100 ms.
    println!("safe stop {delay_ms:.2} ms after the last message started");
    assert!((100.0..=103.0).contains(&delay_ms), "{delay_ms} ms");
}

#[test]
fn corrupted_and_truncated_messages_are_answered_with_the_error_bit_and_never_start_a_travel() {
    let rig = rig();
    let (geometry, _) = geometry(&rig);
    let lw_start = geometry.lw_lowest_landing_m as f64 + 1.0;
    let travel =
        MasterFrame { command: command_byte(Kind::Decelerate, false), data: 500u16.to_be_bytes(), comm: [0; 2] };
    let good = travel.encode();
    let mut corrupted = good;
    corrupted[2] ^= 0x10;
    let unknown = MasterFrame { command: 0x02, ..travel }.encode();
    let out_of_range = MasterFrame { data: 0x8100u16.to_be_bytes(), ..travel }.encode();
    let long = [good.as_slice(), &[0x00]].concat();
    let bad: Vec<Vec<u8>> = vec![corrupted.to_vec(), good[..5].to_vec(), long, unknown.to_vec(), out_of_range.to_vec()];
    // Position, V4, then the bad messages one per cycle, then the good one.
    let mut script: Vec<Vec<u8>> = Vec::new();
    let mut channel = position_message(1000).to_vec();
    for _ in 0..9 {
        let mut comm = [0u8; 2];
        for slot in comm.iter_mut() {
            if !channel.is_empty() {
                *slot = channel.remove(0);
            }
        }
        script.push(MasterFrame { command: command_byte(Kind::Stop, false), data: [0, 0], comm }.encode().to_vec());
    }
    script.push(
        MasterFrame { command: command_byte(Kind::SpeedMode, false), data: Speed::V4.data(), comm: [0; 2] }
            .encode()
            .to_vec(),
    );
    let first_bad = script.len();
    script.extend(bad.iter().cloned());
    let good_at = script.len();
    script.push(good.to_vec());
    let replies = std::cell::RefCell::new(Vec::<(u64, SlaveFrame)>::new());
    let step = std::cell::Cell::new(0u64);
    let run = run_loop(
        &mut |k, _| {
            step.set(k);
            if k % CYCLE_STEPS == 0 {
                script.get((k / CYCLE_STEPS) as usize).cloned().unwrap_or_default()
            } else {
                Vec::new()
            }
        },
        &mut |bytes| {
            for chunk in bytes.chunks(6) {
                let frame = SlaveFrame::decode(chunk.try_into().unwrap()).unwrap();
                replies.borrow_mut().push((step.get(), frame));
            }
        },
        &mut |k, _| k >= (good_at as u64 + 2) * CYCLE_STEPS,
        100_000,
        lw_start,
    );
    let replies = replies.into_inner();
    // One reply per message, in order.
    assert_eq!(replies.len(), good_at + 1, "{replies:?}");
    for (i, (_, reply)) in replies.iter().enumerate() {
        let error = reply.status & S7_MESSAGE_ERROR != 0;
        assert_eq!(error, (first_bad..good_at).contains(&i), "message {i}: status {:#010b}", reply.status);
    }
    let good_step = (good_at as u64 * CYCLE_STEPS) as usize;
    assert!(run.states[..good_step].iter().all(|s| *s == DriveState::Idle), "a bad message started a travel");
    assert!(run.states[good_step..].contains(&DriveState::PreTorque), "the good message starts the travel");
}

#[test]
fn a_dcp3_speed_mode_travel_on_the_emulated_chip_is_bit_identical_to_the_host() {
    let rig = rig();
    let (geometry, _) = geometry(&rig);
    let dir = tempfile::tempdir().unwrap();
    let mut lift = lift_in(dir.path(), geometry.lw_lowest_landing_m as f64 + 1.0);
    // The service port switches the slave to DCP3 (the shadow replays it).
    let mut answer = Vec::new();
    let request = b"set dcp-mode dcp3\n";
    while answer.is_empty() {
        let out = if lift.steps() == 0 { request.as_slice() } else { &[] };
        answer = lift.step(&[], out).unwrap_or_else(|e| panic!("{e:#}")).service_answers;
        assert!(lift.steps() < 100, "no answer from the service port");
    }
    assert_eq!(String::from_utf8_lossy(&answer), "ok dcp-mode dcp3\r\n");
    // Up 1000 mm at V4, then down 300 mm at V2 (a DCP3-only speed).
    let trips = vec![Trip { target_mm: 2000, speed: Speed::V4 }, Trip { target_mm: 1700, speed: Speed::V2 }];
    let master = std::cell::RefCell::new(Master::new(Mode::Dcp3, trips, &rig.drive_config()));
    let run = run_lift(
        &mut lift,
        &mut |k, position| master.borrow_mut().bytes(k, position),
        &mut |_| Vec::new(),
        &mut |replies| master.borrow_mut().receive(replies).unwrap(),
        &mut |_, _| master.borrow().phase() == Phase::Done,
        250_000,
    );
    let master = master.into_inner();
    assert_eq!(master.phase(), Phase::Done, "the sequence did not finish in {} steps", run.steps);
    assert_eq!(run.shadow.port().slave().config().mode, Mode::Dcp3);
    assert!(master.replies.iter().all(|r| r.status & S7_MESSAGE_ERROR == 0), "a good message got the error bit");
    assert_eq!(master.arrivals.len(), 2);
    for arrival in &master.arrivals {
        let error = arrival.position_mm - arrival.trip.target_mm as f64;
        println!(
            "{:?} to {} mm: landed {error:+.2} mm off, {} steps",
            arrival.trip.speed,
            arrival.trip.target_mm,
            arrival.step - arrival.start_step
        );
        assert!(error.abs() < 3.0, "landed {error:.2} mm off the target {} mm", arrival.trip.target_mm);
    }
    // The reference: V4 up (0.4 m/s), V2 down (0.2 m/s), crawl V0 (0.05 m/s) before each stop.
    let split = master.arrivals[0].step as usize;
    let (first, second) = run.ref_speed_mps.split_at(split);
    let rated = rig.drive_config().rated_speed_mps;
    assert_eq!(first.iter().copied().fold(0.0f32, f32::max), rated);
    assert_eq!(second.iter().copied().fold(0.0f32, f32::min), -0.5 * rated);
    let crawl = 0.125 * rated;
    let crawling = |refs: &[f32], v: f32| refs.iter().filter(|&&r| r == v).count();
    println!("crawl: {} and {} steps", crawling(first, crawl), crawling(second, -crawl));
    assert!(crawling(first, crawl) > 400 && crawling(second, -crawl) > 400, "no crawl before the stops");
    assert!(run.states.iter().all(|s| !matches!(s, DriveState::Tripped(_))));
    // The cost of a speed travel's speed-loop tick (its ramp, and the check
    // that it can still stop before the shaft end) on the Cortex-M4F: within
    // the step's real deadline, the valley half a PWM period after the
    // sample (`drive_core::pwm_timing`: 5 312 cycles at 170 MHz and ARR
    // 5312), counting one cycle per instruction (a lower bound of the
    // cycles) and leaving 255 cycles for the conversions before the step starts.
    let divider = rig.drive_config().speed_loop_divider() as u64;
    let offset = lift.steps() - run.steps;
    let in_travel = |tick: bool| -> Vec<f64> {
        (0..run.steps as usize)
            .filter(|&i| run.states[i] == DriveState::Travel && ((offset + i as u64) % divider == 0) == tick)
            .map(|i| run.instructions[i])
            .collect()
    };
    let stats = |v: &[f64]| (v.len(), v.iter().sum::<f64>() / v.len() as f64, v.iter().copied().fold(0.0, f64::max));
    let (ticks, tick_mean, tick_max) = stats(&in_travel(true));
    let (steps, step_mean, step_max) = stats(&in_travel(false));
    println!(
        "instructions in Travel: speed-loop tick {ticks} steps mean {tick_mean:.0} max {tick_max:.0}; \
         current loop only {steps} steps mean {step_mean:.0} max {step_max:.0}"
    );
    let half_period_cycles = rig.pwm_period_counts() as u32;
    assert!(
        drive_core::pwm_timing::compares_in_time(true, 255 + tick_max as u32, half_period_cycles),
        "a speed-loop tick of {tick_max} instructions misses the valley"
    );
}

/// A DCP4 travel with the strategy `car-observer` (the chain observer's
/// task running beside the control step), on the chip if one is given,
/// else on the host build alone.
struct ObserverTravel {
    /// Every step's outputs.
    outputs: Vec<drive_core::ControlOutput>,
    /// The car's acceleration after every step (the plant's), m/s^2.
    car_acceleration_mps2: Vec<f64>,
    /// The drive's speed estimate of every step, rad/s.
    speed_radps: Vec<f64>,
    load: CpuLoad,
    landed_mm: f64,
    shadow: LiftDrive,
}

/// `start_at`: the step at which the lift controller starts (after the
/// service port's answer; the chip's run gives it to the host's, so that
/// both start the travel at the same step).
fn observer_travel(chip: Option<Chip>, lw_start_m: f64, target_mm: i32, start_at: u64) -> (ObserverTravel, u64) {
    let rig = rig();
    let drive = rig.drive_config();
    let m_car = geometry(&rig).1 as f64;
    let mut lift =
        Lift::new(&rig, chip, &default_parameters(&rig), ParamsStatus::None, m_car, lw_start_m).expect("a lift");
    let (answer, _) = lift.ask("set strategy car-observer", 2_000).unwrap_or_else(|e| panic!("{e:#}"));
    assert_eq!(answer, "ok strategy car-observer");
    while lift.steps() < start_at {
        lift.step(&[], &[]).unwrap_or_else(|e| panic!("{e:#}"));
    }
    let started_at = lift.steps();
    let mut master = Master::new(Mode::Dcp4, vec![Trip { target_mm, speed: Speed::V4 }], &drive);
    let mut run = ObserverTravel {
        outputs: Vec::new(),
        car_acceleration_mps2: Vec::new(),
        speed_radps: Vec::new(),
        load: CpuLoad::new(&drive),
        landed_mm: 0.0,
        shadow: *lift.shadow(),
    };
    let started = Instant::now();
    for k in 0..200_000 {
        let out = master.bytes(k, lift.position_mm());
        let step = lift.step(&out, &[]).unwrap_or_else(|e| panic!("{e:#}"));
        master.receive(&step.dcp_replies).unwrap();
        run.load.add(&step);
        run.outputs.push(step.output);
        run.car_acceleration_mps2.push(lift.plant().observe().car_acceleration_mps2);
        run.speed_radps.push(step.output.telemetry.speed_radps as f64);
        if master.phase() == Phase::Done {
            break;
        }
    }
    assert_eq!(master.phase(), Phase::Done, "the travel did not finish");
    run.landed_mm = master.arrivals[0].position_mm;
    run.shadow = *lift.shadow();
    println!("{} steps in {:.1} s", run.outputs.len(), started.elapsed().as_secs_f64());
    (run, started_at)
}

/// The ISO 18738-1 figures of a travel (whole run: max and A95
/// peak-to-peak, mg, max acceleration and deceleration, mg, max jerk,
/// m/s^3; constant speed: max and A95 peak-to-peak, mg), named.
fn ride_figures(run: &ObserverTravel, fs: f64) -> Vec<(&'static str, f64)> {
    let stage = dsp::constant_speed_stage(&run.speed_radps, fs).expect("a constant-speed stage");
    let q = dsp::ride_quality(&run.car_acceleration_mps2, fs, Some(stage)).expect("ride quality");
    let c = q.constant_speed.expect("the constant-speed region");
    vec![
        ("max peak-to-peak, whole run, mg", q.whole_run.max_peak_to_peak_mg),
        ("A95 peak-to-peak, whole run, mg", q.whole_run.a95_peak_to_peak_mg),
        ("max acceleration, mg", q.whole_run.max_acceleration_mg),
        ("max deceleration, mg", q.whole_run.max_deceleration_mg),
        ("max jerk, m/s^3", q.whole_run.max_jerk_mps3),
        ("max peak-to-peak, constant speed, mg", c.max_peak_to_peak_mg),
        ("A95 peak-to-peak, constant speed, mg", c.a95_peak_to_peak_mg),
    ]
}

#[test]
fn a_car_observer_travel_on_the_emulated_chip_rides_as_on_the_host_and_fits_the_core() {
    let rig = rig();
    let (geometry, _) = geometry(&rig);
    let lw_start = geometry.lw_lowest_landing_m as f64 + 1.0;
    let dir = tempfile::tempdir().unwrap();
    let chip = Chip::launch(&default_elf(), Path::new("qemu-system-arm"), dir.path()).expect("the PIL target starts");
    // Up 2000 mm: 3.7 s at the rated speed, where the strategy learns. On
    // the chip every step is checked bit for bit against its host shadow
    // as it runs (outputs, DCP replies, service answers), the observer
    // task's runs included; then the same travel on the host build alone
    // (its own closed loop, the bytes taken as soon as they are sent).
    let (on_chip, start_at) = observer_travel(Some(chip), lw_start, 3000, 0);
    let (on_host, _) = observer_travel(None, lw_start, 3000, start_at);
    // The chip takes the lift controller's bytes when the emulated UART
    // delivers them, the host alone at once: the same travel, shifted.
    let differing = |shift: i64| {
        let (c, h) = if shift >= 0 {
            (&on_chip.outputs[shift as usize..], &on_host.outputs[..])
        } else {
            (&on_chip.outputs[..], &on_host.outputs[(-shift) as usize..])
        };
        c.iter().zip(h).filter(|(c, h)| c != h).count()
    };
    let shift = (-240..=240).min_by_key(|&d| differing(d)).unwrap();
    println!(
        "chip {} steps, host alone {} steps from the same start: the chip's step k + {shift} against the \
         host's step k differs at {} steps",
        on_chip.outputs.len(),
        on_host.outputs.len(),
        differing(shift)
    );
    println!("landed at {:.2} mm, target 3000 mm", on_chip.landed_mm);
    assert!((on_chip.landed_mm - 3000.0).abs() < 3.0);
    // The observer ran on its schedule and its estimate was used.
    let controller = on_chip.shadow.controller();
    assert_eq!(controller.observer_missed_deadlines(), 0);
    assert!(controller.observer_estimate().is_some(), "no estimate reached the controller");
    let task = on_chip.shadow.observer_task().expect("the observer's task");
    assert_eq!(task.observer().restarts(), 0);
    assert!(on_chip.load.observer_runs > 10_000, "{} observer runs", on_chip.load.observer_runs);
    // Ride quality of the car, chip against host: within 1 dB each.
    let fs = rig.control.current_loop_hz;
    let (chip, host) = (ride_figures(&on_chip, fs), ride_figures(&on_host, fs));
    for ((name, c), (_, h)) in chip.iter().zip(&host) {
        let db = 20.0 * (c / h).log10();
        println!("{name:<40} chip {c:9.3} host {h:9.3} {db:+.2} dB");
        assert!(h.is_finite() && *h > 0.0 && db.abs() <= 1.0, "{name}: chip {c}, host {h}");
    }
    // The host-sim closed loop (`host-sim travel`'s: the plant sampled at
    // the rig's 16 384 Hz, the PWM outputs acting from the next half
    // period, the travel commanded directly) with the same strategy on the
    // same travel: within 1 dB each too.
    let travel_loop = {
        let drive = rig.drive_config();
        let mut controller = drive_core::Controller::new(&drive);
        let table = default_parameters(&rig).table;
        controller.install_compensation(drive_core::ripple::Strategy::CarObserver, &table, &rig.observer_model());
        let task = drive_core::observer::ObserverTask::for_model(&rig.observer_model()).unwrap();
        let mut observed = closed_loop::ObservedController { controller: &mut controller, task };
        let spec = closed_loop::TravelSpec {
            m_car_kg: closed_loop::pil::dcp::geometry(&rig).1 as f64,
            direction: drive_core::config::Direction::Up,
            lw_start_m: lw_start,
            lw_end_m: lw_start + 2.0,
        };
        let options = closed_loop::SimOptions::for_rig(&rig);
        let run = closed_loop::simulate_travel_with(&rig, &spec, &options, &mut observed, None, None).unwrap();
        let stage = dsp::constant_speed_stage(&run.speed_radps, run.sample_rate_hz).unwrap();
        let q = dsp::ride_quality(&run.acc_car_mps2, run.sample_rate_hz, Some(stage)).unwrap();
        let c = q.constant_speed.unwrap();
        [
            q.whole_run.max_peak_to_peak_mg,
            q.whole_run.a95_peak_to_peak_mg,
            q.whole_run.max_acceleration_mg,
            q.whole_run.max_deceleration_mg,
            q.whole_run.max_jerk_mps3,
            c.max_peak_to_peak_mg,
            c.a95_peak_to_peak_mg,
        ]
    };
    for ((name, c), t) in chip.iter().zip(travel_loop) {
        let db = 20.0 * (c / t).log10();
        println!("{name:<40} chip {c:9.3} host-sim travel loop {t:9.3} {db:+.2} dB");
        assert!(t.is_finite() && t > 0.0 && db.abs() <= 1.0, "{name}: chip {c}, host-sim travel loop {t}");
    }
    // The load of the control interrupt and the observer task, under 60 %
    // of a 170 MHz core (instructions counted under -icount, not time), on
    // average and in the busiest speed-loop period (8 PWM periods and one
    // observer run).
    println!("{}", on_chip.load.summary());
    assert!(on_chip.load.mean_percent() < 60.0, "{}", on_chip.load.summary());
    assert!(on_chip.load.worst_period_percent() < 60.0, "{}", on_chip.load.summary());
    // Every step's compares (the learning of the strategy's ticks left for
    // after them) within the real deadline, the valley half a PWM period
    // after the sample, one cycle counted per instruction and 255 cycles
    // for the conversions; the whole period's work within the period.
    let half_period_cycles = rig.pwm_period_counts() as u32;
    assert!(
        drive_core::pwm_timing::compares_in_time(true, 255 + on_chip.load.control_max as u32, half_period_cycles),
        "a step of {} instructions to its outputs misses the valley",
        on_chip.load.control_max
    );
    assert!(
        255.0 + on_chip.load.period_max < 2.0 * half_period_cycles as f64,
        "a period's work of {} instructions overruns the period",
        on_chip.load.period_max
    );
}

#[test]
fn host_sim_pil_dcp_runs_the_travels_and_prints_one_row_per_travel() {
    let out = tempfile::tempdir().unwrap();
    let output = std::process::Command::new(env!("CARGO_BIN_EXE_host-sim"))
        .args(["pil", "--dcp", "--landings", "1300,1100", "--start-mm", "1000", "--quiet", "--out"])
        .arg(out.path())
        .arg("--elf")
        .arg(default_elf())
        .output()
        .expect("host-sim runs");
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(output.status.success(), "{stdout}\n{}", String::from_utf8_lossy(&output.stderr));
    println!("{stdout}");
    assert!(stdout.contains("bit-identical to the host build"), "{stdout}");
    // One row per travel: number, from, to, landed, error, steps, time, peak speed.
    let rows: Vec<Vec<&str>> = stdout
        .lines()
        .map(|l| l.split_whitespace().collect::<Vec<_>>())
        .filter(|w| w.len() == 8 && w[0].parse::<u32>().is_ok())
        .collect();
    assert_eq!(rows.len(), 2, "{stdout}");
    for (row, target) in rows.iter().zip([1300.0, 1100.0]) {
        assert_eq!(row[2].parse::<f64>().unwrap(), target);
        let error: f64 = row[4].parse().unwrap();
        assert!(error.abs() < 3.0, "landed {error} mm off: {row:?}");
        let peak: f64 = row[7].parse().unwrap();
        assert!(peak > 0.1 && peak < 0.45, "peak speed {peak} m/s");
    }
    let csv = std::fs::read_to_string(out.path().join("dcp_travels.csv")).unwrap();
    assert_eq!(csv.lines().count(), 3, "{csv}");
    // A landing outside the shaft: a clear error, no QEMU started.
    let output = std::process::Command::new(env!("CARGO_BIN_EXE_host-sim"))
        .args(["pil", "--dcp", "--landings", "99999", "--out"])
        .arg(out.path().join("bad"))
        .output()
        .unwrap();
    assert!(!output.status.success());
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(stderr.contains("--landings: 99999 mm is out of range"), "{stderr}");
}
