//! Step 3 of the diagnosis: where the gap of the nominal model lies, along
//! the signal chain (electrical -> drive -> mechanical), in time (travel
//! phases) and in frequency (bands; the strongest cells; the natural
//! frequencies found in the data against the model's).

use super::attribute::Target;
use super::measure::{gap_of_cells, CellGap};
use super::signals::{ChainSignals, Channel, Phase, Subsystem};
use super::spectra::Bands;
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

/// Locates the gap of the nominal model from its cells (`cells[r]` for
/// recording `r`), the recordings' gaps (closed loop and replay) and the
/// spectra.
pub fn locate(
    cells: &[Vec<CellGap>],
    recordings: &[RecordingGap],
    bands: &Bands,
    targets: &[Target],
    measured: &[ChainSignals],
) -> Location {
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
    let top = channels.iter().map(|c| c.excess_db).fold(0.0, f64::max);
    let of = |s: Subsystem| channels.iter().filter(|c| c.subsystem == s).map(|c| c.excess_db).fold(0.0, f64::max);
    let (electrical, drive, mechanical) = (of(Subsystem::Electrical), of(Subsystem::Drive), of(Subsystem::Mechanical));
    let travels: Vec<&RecordingGap> = recordings.iter().filter(|r| r.replay_acceleration_excess_db.is_some()).collect();
    let closed =
        travels.iter().filter_map(|r| r.closed_loop_acceleration_excess_db).sum::<f64>() / travels.len().max(1) as f64;
    let replay =
        travels.iter().filter_map(|r| r.replay_acceleration_excess_db).sum::<f64>() / travels.len().max(1) as f64;
    let (subsystem, reasoning) = if electrical >= 0.5 * top && electrical > 1.0 {
        (
            Subsystem::Electrical,
            format!(
                "the currents already differ (excess {electrical:.2} dB on i_d/torque, against {drive:.2} dB on the \
                 speed and {mechanical:.2} dB on the accelerations): the gap enters at the inverter, machine or \
                 current control"
            ),
        )
    } else if !travels.is_empty() && closed > 1.0 && replay < 0.5 * closed {
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
                if travels.is_empty() {
                    String::new()
                } else {
                    format!(", and the replay with the measured shaft motion does not remove it ({replay:.2} dB against {closed:.2} dB below 80 Hz)")
                }
            ),
        )
    };
    let channel = channels
        .iter()
        .filter(|c| c.subsystem == subsystem)
        .max_by(|a, b| a.excess_db.total_cmp(&b.excess_db))
        .or_else(|| channels.iter().max_by(|a, b| a.excess_db.total_cmp(&b.excess_db)))
        .map_or(Channel::CarAcceleration, |c| c.channel);
    let on_channel: Vec<&CellGap> = cells.iter().flatten().filter(|c| c.channel == channel).collect();
    let slice = |label: String, d: Vec<f64>| SliceGap {
        slice: label,
        rms_d_db: rms(&d),
        mean_d_db: d.iter().sum::<f64>() / d.len().max(1) as f64,
    };
    let mut phases = Vec::new();
    for phase in [Phase::Start, Phase::Acceleration, Phase::Constant, Phase::Deceleration, Phase::Stop, Phase::Decay] {
        let d: Vec<f64> = on_channel.iter().filter(|c| c.phase == phase).map(|c| c.d_db).collect();
        if !d.is_empty() {
            phases.push((phase, slice(phase.name().to_string(), d)));
        }
    }
    let mut band_slices = Vec::new();
    for b in 0..bands.len() + super::spectra::LINE_ORDERS.len() {
        let d: Vec<f64> = on_channel.iter().filter(|c| c.band == b).map(|c| c.d_db).collect();
        if !d.is_empty() {
            band_slices.push((bands.label(b), slice(bands.label(b), d)));
        }
    }
    let phase = phases.iter().max_by(|a, b| a.1.rms_d_db.total_cmp(&b.1.rms_d_db)).map_or(Phase::Constant, |p| p.0);
    let band =
        band_slices.iter().max_by(|a, b| a.1.rms_d_db.total_cmp(&b.1.rms_d_db)).map_or(String::new(), |b| b.0.clone());
    let mut strongest: Vec<StrongCell> = cells
        .iter()
        .zip(targets)
        .flat_map(|(c, t)| {
            c.iter().map(move |x| StrongCell {
                recording: t.stem.clone(),
                channel: x.channel,
                phase: x.phase,
                band: bands.label(x.band),
                d_db: x.d_db,
            })
        })
        .collect();
    strongest.sort_by(|a, b| b.d_db.abs().total_cmp(&a.d_db.abs()));
    strongest.truncate(10);
    let mut natural_frequencies = Vec::new();
    for (t, m) in targets.iter().zip(measured) {
        let phase = if m.phases.iter().any(|(p, _)| *p == Phase::Decay) { Phase::Decay } else { Phase::Stop };
        let seg = super::spectra::Segmentation::of(m);
        let spectra = super::spectra::ChainSpectra::compute(m, &seg, bands);
        if let (Some(measured_hz), Some(model_hz)) = (peak_hz(&spectra, phase), peak_hz(&t.nominal, phase)) {
            natural_frequencies.push(NaturalFrequency { recording: t.stem.clone(), phase, measured_hz, model_hz });
        }
    }
    Location {
        subsystem,
        reasoning,
        channel,
        phase,
        band,
        channels,
        phases: phases.into_iter().map(|p| p.1).collect(),
        bands: band_slices.into_iter().map(|b| b.1).collect(),
        strongest_cells: strongest,
        natural_frequencies,
    }
}
