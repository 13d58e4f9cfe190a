//! Step 3 of the diagnosis: where the gap of the nominal model lies, along
//! the signal chain (electrical -> drive -> mechanical), in time (travel
//! phases) and in frequency (bands; the strongest cells; the natural
//! frequencies found in the data against the model's).

use super::measure::{gap_of_cells, CellGap};
use super::signals::{Channel, Phase, Subsystem};
use super::spectra::{Bands, ChainSpectra};
use super::target::Target;
use super::RecordingGap;

/// A channel's share of the gap.
#[derive(Clone, Debug, serde::Serialize)]
pub struct ChannelGap {
    /// Channel.
    pub channel: Channel,
    /// Subsystem it observes.
    pub subsystem: Subsystem,
    /// Mean excess gap over the recordings that have it, dB.
    pub excess_db: f64,
}

/// RMS of the cell gaps `d` of a phase or band, dB.
#[derive(Clone, Debug, serde::Serialize)]
pub struct SliceGap {
    /// Phase name or band as text (`lo-hi Hz`).
    pub slice: String,
    /// RMS `d` over the located channel's cells, dB.
    pub rms_d_db: f64,
    /// Mean `d` (positive: the data hold more than the model), dB.
    pub mean_d_db: f64,
}

/// One cell where the gap is largest.
#[derive(Clone, Debug, serde::Serialize)]
pub struct StrongCell {
    /// Recording.
    pub recording: String,
    /// Channel.
    pub channel: Channel,
    /// Phase.
    pub phase: Phase,
    /// Band (`lo-hi Hz`) or line (`order n`).
    pub band: String,
    /// `10 log10(measured / model)`, dB.
    pub d_db: f64,
}

/// A natural frequency in the data against the model's.
#[derive(Clone, Debug, serde::Serialize)]
pub struct NaturalFrequency {
    /// Recording.
    pub recording: String,
    /// Where it was found (`stop` phase of a travel or a decay).
    pub phase: Phase,
    /// Strongest car-acceleration peak in the data, 2-400 Hz, Hz.
    pub measured_hz: f64,
    /// The same in the nominal model's run, Hz.
    pub model_hz: f64,
}

/// Where the gap lies.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Location {
    /// The subsystem where the gap enters the chain.
    pub subsystem: Subsystem,
    /// Why.
    pub reasoning: String,
    /// The channel with the largest excess gap.
    pub channel: Channel,
    /// The phase with the largest RMS gap on that channel.
    pub phase: Phase,
    /// The band (`lo-hi Hz`) or line (`order n`) with the largest RMS gap on
    /// that channel.
    pub band: String,
    /// Per channel.
    pub channels: Vec<ChannelGap>,
    /// Per phase, on the located channel.
    pub phases: Vec<SliceGap>,
    /// Per band, on the located channel.
    pub bands: Vec<SliceGap>,
    /// The ten strongest cells.
    pub strongest_cells: Vec<StrongCell>,
    /// Natural frequencies, data against model.
    pub natural_frequencies: Vec<NaturalFrequency>,
}

fn rms(v: &[f64]) -> f64 {
    (v.iter().map(|x| x * x).sum::<f64>() / v.len().max(1) as f64).sqrt()
}

/// Strongest car-acceleration peak (Hz) between 2 and 400 Hz of `phase`,
/// from the measured and the nominal spectra.
fn peak_hz(spectra: &super::spectra::ChainSpectra, phase: Phase) -> Option<f64> {
    let s = spectra.channel(Channel::CarAcceleration)?;
    let seg = &spectra.segmentation;
    let df = seg.sample_rate_hz / seg.segment_len as f64;
    let mut power = vec![0.0; s.bins];
    for (k, (p, _)) in seg.segments.iter().enumerate() {
        if *p == phase {
            for (b, p) in power.iter_mut().enumerate() {
                *p += s.data[k * s.bins + b].norm_sqr() * s.scale[k];
            }
        }
    }
    let lo = (2.0 / df).ceil() as usize;
    let hi = ((400.0 / df) as usize).min(s.bins.saturating_sub(1));
    (lo..=hi).max_by(|&a, &b| power[a].total_cmp(&power[b])).filter(|&b| power[b] > 0.0).map(|b| b as f64 * df)
}

/// Largest excess gap per subsystem, from the per-channel gaps.
#[derive(Clone, Copy, Debug, PartialEq)]
struct SubsystemExcess {
    /// Largest excess gap of any channel (0 when none is positive), dB.
    top_db: f64,
    /// Largest excess gap of the electrical channels (torque), dB.
    electrical_db: f64,
    /// Largest excess gap of the drive channels (speed), dB.
    drive_db: f64,
    /// Largest excess gap of the mechanical channels (accelerations), dB.
    mechanical_db: f64,
}

/// The travels' acceleration gaps below 80 Hz, closed loop against replay.
#[derive(Clone, Copy, Debug, PartialEq)]
struct ShaftReplay {
    /// Number of recordings with a replay (the travels).
    travels: usize,
    /// Mean closed-loop acceleration excess gap over those travels, dB.
    closed_loop_db: f64,
    /// Mean replay acceleration excess gap over those travels, dB.
    replay_db: f64,
}

/// Where the gap enters the chain, and why.
#[derive(Clone, Debug, PartialEq)]
struct Entry {
    /// The subsystem.
    subsystem: Subsystem,
    /// The reasoning, in words.
    reasoning: String,
}

/// A phase's slice of the gap on the located channel.
#[derive(Clone, Debug)]
struct PhaseGap {
    /// The phase.
    phase: Phase,
    /// Its RMS and mean `d`.
    gap: SliceGap,
}

/// Step: every channel's mean excess gap over the recordings that have it,
/// in signal-chain order ([`Channel::ALL`]).
fn channel_gaps(cells: &[Vec<CellGap>]) -> Vec<ChannelGap> {
    let mut channels = Vec::new();
    for channel in Channel::ALL {
        let per: Vec<f64> = cells
            .iter()
            .filter(|c| c.iter().any(|x| x.channel == channel))
            .map(|c| gap_of_cells(c.iter().filter(|x| x.channel == channel)).excess_db())
            .collect();
        if !per.is_empty() {
            channels.push(ChannelGap {
                channel,
                subsystem: channel.subsystem(),
                excess_db: per.iter().sum::<f64>() / per.len() as f64,
            });
        }
    }
    channels
}

impl SubsystemExcess {
    /// Step: the largest excess gap of all channels and of each subsystem's.
    fn of(channels: &[ChannelGap]) -> Self {
        let top = channels.iter().map(|c| c.excess_db).fold(0.0, f64::max);
        let of = |s: Subsystem| channels.iter().filter(|c| c.subsystem == s).map(|c| c.excess_db).fold(0.0, f64::max);
        SubsystemExcess {
            top_db: top,
            electrical_db: of(Subsystem::Electrical),
            drive_db: of(Subsystem::Drive),
            mechanical_db: of(Subsystem::Mechanical),
        }
    }
}

impl ShaftReplay {
    /// Step: the mean closed-loop and replay acceleration gaps of the
    /// recordings that have a replay.
    fn of(recordings: &[RecordingGap]) -> Self {
        let travels: Vec<&RecordingGap> =
            recordings.iter().filter(|r| r.replay_acceleration_excess_db.is_some()).collect();
        let closed = travels.iter().filter_map(|r| r.closed_loop_acceleration_excess_db).sum::<f64>()
            / travels.len().max(1) as f64;
        let replay =
            travels.iter().filter_map(|r| r.replay_acceleration_excess_db).sum::<f64>() / travels.len().max(1) as f64;
        ShaftReplay { travels: travels.len(), closed_loop_db: closed, replay_db: replay }
    }
}

/// Step: the subsystem where the gap enters the chain. Electrical when the
/// currents carry at least half the largest gap (and over 1 dB); the drive
/// when the replay with the measured shaft motion removes more than half of
/// the closed loop's acceleration gap (over 1 dB); the mechanics otherwise.
fn entry(excess: &SubsystemExcess, shaft: &ShaftReplay) -> Entry {
    let SubsystemExcess { top_db: top, electrical_db: electrical, drive_db: drive, mechanical_db: mechanical } =
        *excess;
    let ShaftReplay { travels, closed_loop_db: closed, replay_db: replay } = *shaft;
    let (subsystem, reasoning) = if electrical >= 0.5 * top && electrical > 1.0 {
        (
            Subsystem::Electrical,
            format!(
                "the currents already differ (excess {electrical:.2} dB on i_d/torque, against {drive:.2} dB on the \
                 speed and {mechanical:.2} dB on the accelerations): the gap enters at the inverter, machine or \
                 current control"
            ),
        )
    } else if travels != 0 && closed > 1.0 && replay < 0.5 * closed {
        (
            Subsystem::Drive,
            format!(
                "driven by the measured shaft motion the nominal mechanics reproduces the accelerations below 80 Hz \
                 (replay excess {replay:.2} dB against {closed:.2} dB in closed loop): the gap lies in how the shaft \
                 moves (drive, speed control, torque at the shaft)"
            ),
        )
    } else {
        (
            Subsystem::Mechanical,
            format!(
                "the accelerations carry the gap (excess {mechanical:.2} dB; currents {electrical:.2} dB, speed \
                 {drive:.2} dB){}: the gap lies in the ropes, car, counterweight or their sensors",
                if travels == 0 {
                    String::new()
                } else {
                    format!(", and the replay with the measured shaft motion does not remove it ({replay:.2} dB against {closed:.2} dB below 80 Hz)")
                }
            ),
        )
    };
    Entry { subsystem, reasoning }
}

/// Step: the channel of `subsystem` with the largest excess gap (of any
/// subsystem when it has none; the car acceleration when there is none).
fn located_channel(channels: &[ChannelGap], subsystem: Subsystem) -> Channel {
    channels
        .iter()
        .filter(|c| c.subsystem == subsystem)
        .max_by(|a, b| a.excess_db.total_cmp(&b.excess_db))
        .or_else(|| channels.iter().max_by(|a, b| a.excess_db.total_cmp(&b.excess_db)))
        .map_or(Channel::CarAcceleration, |c| c.channel)
}

/// The RMS and mean of the gaps `d` (dB) of one slice, labelled.
fn slice_gap(label: String, d: Vec<f64>) -> SliceGap {
    SliceGap { slice: label, rms_d_db: rms(&d), mean_d_db: d.iter().sum::<f64>() / d.len().max(1) as f64 }
}

/// Step: per travel phase (in time order, the phases present), the slice
/// of the gap of the cells `on_channel`.
fn phase_gaps(on_channel: &[&CellGap]) -> Vec<PhaseGap> {
    let mut phases = Vec::new();
    for phase in [Phase::Start, Phase::Acceleration, Phase::Constant, Phase::Deceleration, Phase::Stop, Phase::Decay] {
        let d: Vec<f64> = on_channel.iter().filter(|c| c.phase == phase).map(|c| c.d_db).collect();
        if !d.is_empty() {
            phases.push(PhaseGap { phase, gap: slice_gap(phase.name().to_string(), d) });
        }
    }
    phases
}

/// Step: per band, then per line (the cells' band indices in order, those
/// present), the slice of the gap of the cells `on_channel`, labelled by
/// [`Bands::label`].
fn band_gaps(on_channel: &[&CellGap], bands: &Bands) -> Vec<SliceGap> {
    let mut band_slices = Vec::new();
    for b in 0..bands.len() + bands.line_orders.len() {
        let d: Vec<f64> = on_channel.iter().filter(|c| c.band == b).map(|c| c.d_db).collect();
        if !d.is_empty() {
            band_slices.push(slice_gap(bands.label(b), d));
        }
    }
    band_slices
}

/// Step: the ten cells of every recording (`cells[r]` named `stems[r]`)
/// with the largest `|d|`, largest first.
fn strongest_cells(cells: &[Vec<CellGap>], stems: &[&str], bands: &Bands) -> Vec<StrongCell> {
    let mut strongest: Vec<StrongCell> = cells
        .iter()
        .zip(stems)
        .flat_map(|(c, t)| {
            c.iter().map(move |x| StrongCell {
                recording: t.to_string(),
                channel: x.channel,
                phase: x.phase,
                band: bands.label(x.band),
                d_db: x.d_db,
            })
        })
        .collect();
    strongest.sort_by(|a, b| b.d_db.abs().total_cmp(&a.d_db.abs()));
    strongest.truncate(10);
    strongest
}

/// Step: per recording, the strongest car-acceleration peak of its decay (or
/// its stop) in the data against the nominal model's.
fn natural_frequencies(targets: &[Target], measured: &[ChainSpectra]) -> Vec<NaturalFrequency> {
    let mut natural_frequencies = Vec::new();
    for (t, spectra) in targets.iter().zip(measured) {
        let decay = matches!(t.recording.meta.kind, recording::RecordingKind::FreeDecay { .. });
        let phase = if decay { Phase::Decay } else { Phase::Stop };
        if let (Some(measured_hz), Some(model_hz)) = (peak_hz(spectra, phase), peak_hz(&t.nominal, phase)) {
            natural_frequencies.push(NaturalFrequency { recording: t.stem.clone(), phase, measured_hz, model_hz });
        }
    }
    natural_frequencies
}

/// Locates the gap of the nominal model from its cells (`cells[r]` for
/// recording `r`), the recordings' gaps (closed loop and replay) and the
/// spectra (`measured`, each target's measured ones).
pub fn locate(
    cells: &[Vec<CellGap>],
    recordings: &[RecordingGap],
    bands: &Bands,
    targets: &[Target],
    measured: &[ChainSpectra],
) -> Location {
    let channels = channel_gaps(cells);
    let Entry { subsystem, reasoning } = entry(&SubsystemExcess::of(&channels), &ShaftReplay::of(recordings));
    let channel = located_channel(&channels, subsystem);
    let on_channel: Vec<&CellGap> = cells.iter().flatten().filter(|c| c.channel == channel).collect();
    let phases = phase_gaps(&on_channel);
    let band_slices = band_gaps(&on_channel, bands);
    let phase =
        phases.iter().max_by(|a, b| a.gap.rms_d_db.total_cmp(&b.gap.rms_d_db)).map_or(Phase::Constant, |p| p.phase);
    let band =
        band_slices.iter().max_by(|a, b| a.rms_d_db.total_cmp(&b.rms_d_db)).map_or(String::new(), |b| b.slice.clone());
    let stems: Vec<&str> = targets.iter().map(|t| t.stem.as_str()).collect();
    Location {
        subsystem,
        reasoning,
        channel,
        phase,
        band,
        channels,
        phases: phases.into_iter().map(|p| p.gap).collect(),
        bands: band_slices,
        strongest_cells: strongest_cells(cells, &stems, bands),
        natural_frequencies: natural_frequencies(targets, measured),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cell(channel: Channel, phase: Phase, band: usize, d_db: f64) -> CellGap {
        CellGap {
            channel,
            phase,
            band,
            measured: 1.0,
            simulated: 1.0,
            d_db,
            noise_db: 0.0,
            noise_bound_db: 0.0,
            tolerance_db: 0.0,
        }
    }

    fn bands() -> Bands {
        Bands { edges_hz: vec![(1.0, 2.0), (2.0, 4.0)], bin_band: Vec::new(), line_orders: vec![1] }
    }

    fn recording(closed: Option<f64>, replay: Option<f64>) -> RecordingGap {
        RecordingGap {
            recording: "r".to_string(),
            kind: "travel",
            nominal: Default::default(),
            nominal_excess_db: 0.0,
            closed_loop_acceleration_excess_db: closed,
            replay_acceleration_excess_db: replay,
            explained: None,
            explained_excess_db: None,
            begins_in_motion: false,
        }
    }

    fn channel_gap(channel: Channel, excess_db: f64) -> ChannelGap {
        ChannelGap { channel, subsystem: channel.subsystem(), excess_db }
    }

    #[test]
    fn channel_gaps_average_over_the_recordings_that_have_the_channel() {
        // Without noise or tolerance a recording's excess is the RMS of its d.
        let mut beyond = cell(Channel::CarAcceleration, Phase::Stop, 0, -5.0);
        (beyond.noise_bound_db, beyond.tolerance_db) = (2.0, 1.0); // 5 - 2 - 1 = 2 dB beyond
        let cells = vec![
            vec![cell(Channel::Torque, Phase::Start, 0, 3.0), cell(Channel::Torque, Phase::Stop, 1, -3.0)],
            vec![beyond, cell(Channel::Torque, Phase::Start, 0, 1.0)],
        ];
        let gaps = channel_gaps(&cells);
        assert_eq!(gaps.len(), 2);
        assert_eq!((gaps[0].channel, gaps[0].subsystem), (Channel::Torque, Subsystem::Electrical));
        assert!((gaps[0].excess_db - 2.0).abs() < 1e-12, "(3 + 1) / 2: {}", gaps[0].excess_db);
        assert_eq!((gaps[1].channel, gaps[1].subsystem), (Channel::CarAcceleration, Subsystem::Mechanical));
        assert!((gaps[1].excess_db - 2.0).abs() < 1e-12, "{}", gaps[1].excess_db);
    }

    #[test]
    fn subsystem_excess_takes_the_largest_channel_and_never_below_zero() {
        let channels = [
            channel_gap(Channel::Torque, 0.4),
            channel_gap(Channel::CarAcceleration, 1.5),
            channel_gap(Channel::CounterweightAcceleration, 2.5),
        ];
        let e = SubsystemExcess::of(&channels);
        assert_eq!(e, SubsystemExcess { top_db: 2.5, electrical_db: 0.4, drive_db: 0.0, mechanical_db: 2.5 });
    }

    #[test]
    fn shaft_replay_averages_the_travels_only() {
        let r =
            ShaftReplay::of(&[recording(Some(2.0), Some(1.0)), recording(None, None), recording(Some(4.0), Some(0.0))]);
        assert_eq!(r, ShaftReplay { travels: 2, closed_loop_db: 3.0, replay_db: 0.5 });
        assert_eq!(ShaftReplay::of(&[]), ShaftReplay { travels: 0, closed_loop_db: 0.0, replay_db: 0.0 });
    }

    #[test]
    fn entry_follows_the_chain() {
        let excess = |e, d, m| SubsystemExcess {
            top_db: f64::max(e, f64::max(d, m)),
            electrical_db: e,
            drive_db: d,
            mechanical_db: m,
        };
        let no_travel = ShaftReplay { travels: 0, closed_loop_db: 0.0, replay_db: 0.0 };
        let replayed = ShaftReplay { travels: 1, closed_loop_db: 3.0, replay_db: 1.0 };
        let not_replayed = ShaftReplay { travels: 1, closed_loop_db: 3.0, replay_db: 2.0 };
        // Currents with at least half the largest gap, over 1 dB.
        let e = entry(&excess(1.5, 0.2, 3.0), &replayed);
        assert_eq!(e.subsystem, Subsystem::Electrical);
        assert!(e.reasoning.contains("excess 1.50 dB on i_d/torque"), "{}", e.reasoning);
        // Currents under half: the replay decides.
        assert_eq!(entry(&excess(1.4, 0.2, 3.0), &replayed).subsystem, Subsystem::Drive);
        assert_eq!(entry(&excess(1.0, 0.2, 1.5), &replayed).subsystem, Subsystem::Drive);
        let m = entry(&excess(1.0, 0.2, 1.5), &not_replayed);
        assert_eq!(m.subsystem, Subsystem::Mechanical);
        assert!(m.reasoning.contains("(2.00 dB against 3.00 dB below 80 Hz)"), "{}", m.reasoning);
        let m = entry(&excess(1.0, 0.2, 1.5), &no_travel);
        assert_eq!(m.subsystem, Subsystem::Mechanical);
        assert!(!m.reasoning.contains("replay"), "{}", m.reasoning);
    }

    #[test]
    fn located_channel_prefers_the_subsystem_then_any_then_the_car() {
        let channels = [
            channel_gap(Channel::Torque, 4.0),
            channel_gap(Channel::CarAcceleration, 1.0),
            channel_gap(Channel::CounterweightAcceleration, 2.0),
        ];
        assert_eq!(located_channel(&channels, Subsystem::Mechanical), Channel::CounterweightAcceleration);
        assert_eq!(located_channel(&channels, Subsystem::Drive), Channel::Torque);
        assert_eq!(located_channel(&[], Subsystem::Drive), Channel::CarAcceleration);
    }

    #[test]
    fn phase_and_band_slices_in_order_with_rms_and_mean() {
        let cells = [
            cell(Channel::Torque, Phase::Stop, 2, 3.0),
            cell(Channel::Torque, Phase::Stop, 0, -4.0),
            cell(Channel::Torque, Phase::Start, 2, 2.0),
        ];
        let on: Vec<&CellGap> = cells.iter().collect();
        let phases = phase_gaps(&on);
        assert_eq!(phases.iter().map(|p| p.phase).collect::<Vec<_>>(), [Phase::Start, Phase::Stop]);
        assert_eq!(phases[1].gap.slice, "stop");
        assert!((phases[1].gap.rms_d_db - 12.5f64.sqrt()).abs() < 1e-12);
        assert!((phases[1].gap.mean_d_db + 0.5).abs() < 1e-12);
        let b = band_gaps(&on, &bands());
        assert_eq!(b.iter().map(|s| s.slice.as_str()).collect::<Vec<_>>(), ["1.0-2.0 Hz", "order 1"]);
        assert!((b[1].rms_d_db - 6.5f64.sqrt()).abs() < 1e-12);
        assert!((b[1].mean_d_db - 2.5).abs() < 1e-12);
    }

    #[test]
    fn strongest_cells_keeps_the_ten_largest_magnitudes() {
        let cells = vec![
            (0..6).map(|i| cell(Channel::Torque, Phase::Stop, 0, i as f64)).collect::<Vec<_>>(),
            (0..6).map(|i| cell(Channel::Speed, Phase::Start, 1, -(i as f64) - 0.5)).collect::<Vec<_>>(),
        ];
        let s = strongest_cells(&cells, &["a", "b"], &bands());
        let d: Vec<f64> = s.iter().map(|c| c.d_db).collect();
        assert_eq!(d, [-5.5, 5.0, -4.5, 4.0, -3.5, 3.0, -2.5, 2.0, -1.5, 1.0]);
        assert_eq!((s[0].recording.as_str(), s[0].channel, s[0].band.as_str()), ("b", Channel::Speed, "2.0-4.0 Hz"));
        assert_eq!((s[1].recording.as_str(), s[1].phase), ("a", Phase::Stop));
    }
}
