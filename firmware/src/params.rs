//! The drive's parameters in flash: one `drive_core::param_store` record
//! (strategy, harmonic table, car mass, encoder offset; versioned,
//! CRC-32 checked) kept under key 0 of a `sequential-storage` map, which
//! spreads the writes over [`STORE_PAGES`] flash pages (wear levelling) and
//! survives a power loss during a write (the previous record stays).
//!
//! Where: the last 16 KiB of the 512 KiB flash (bank 2 in the factory
//! dual-bank layout, so erasing and writing it does not stall code running
//! from bank 1); `memory.x` gives the program only the first 496 KiB.
//!
//! A record that fails any check (magic, version, length, CRC, values) is
//! refused whole: the drive runs with its defaults and the log says why.
//!
//! Writing (the service port's `save`): the G4's flash driver erases and
//! programs inside a critical section, and a page erase takes tens of ms,
//! so the service task writes only with the drive idle and the control
//! interrupt paused (`control::pause_if_idle`, inverter off and brake
//! applied throughout), then resumes it without counting the pause as a
//! missed deadline. Untested on the board: the pause must stay under the
//! independent watchdog's ~100 ms (a page erase is 22-40 ms on the G4), and
//! DCP bytes arriving during it may be lost (the master repeats after the
//! error answer).

use defmt::{info, warn};
use drive_core::param_store::{DriveParameters, RecordError, MAX_RECORD};
use drive_core::service::ParamsStatus;
use embassy_embedded_hal::adapter::BlockingAsync;
use embassy_stm32::flash::{Blocking, Flash};
use embassy_stm32::peripherals::FLASH;
use embassy_stm32::Peri;
use sequential_storage::cache::{Cache, Uncached};
use sequential_storage::map::{MapConfig, MapStorage};

/// Offset of the store from the start of flash, bytes.
pub const STORE_START: u32 = 0x7_C000;
/// End of the store (the end of the 512 KiB flash), bytes.
pub const STORE_END: u32 = 0x8_0000;
/// Flash pages of the store (4 KiB each).
pub const STORE_PAGES: u32 = (STORE_END - STORE_START) / 4096;

/// The map key of the parameter record.
const KEY: u8 = 0;

type Store = MapStorage<u8, BlockingAsync<Flash<'static, Blocking>>, Cache<Uncached, Uncached, Uncached, u8>>;

/// The parameter store over the flash driver.
pub struct ParamStore(Store);

impl ParamStore {
    /// The store in its flash pages.
    pub fn new(flash: Peri<'static, FLASH>) -> Self {
        Self(MapStorage::new(
            BlockingAsync::new(Flash::new_blocking(flash)),
            const { MapConfig::new(STORE_START..STORE_END) },
            Cache::new_uncached(),
        ))
    }

    /// The stored parameters, if a record is stored and passes every
    /// check, and what became of the record (for the service port's `get params`).
    pub async fn load(&mut self) -> (Option<DriveParameters>, ParamsStatus) {
        load(&mut self.0).await
    }

    /// Writes `parameters` as the stored record (call with the control
    /// interrupt paused, see the module doc); whether it was written.
    pub async fn save(&mut self, parameters: &DriveParameters) -> bool {
        let mut record = [0u8; MAX_RECORD];
        let n = parameters.encode(&mut record);
        let mut buffer = [0u8; MAX_RECORD + 16];
        match self.0.store_item(&mut buffer, &KEY, &&record[..n]).await {
            Ok(()) => {
                info!("parameters: record written ({=usize} bytes)", n);
                true
            }
            Err(e) => {
                warn!("parameters: record not written: {}", e);
                false
            }
        }
    }
}

async fn load(store: &mut Store) -> (Option<DriveParameters>, ParamsStatus) {
    // Key, value and the storage's own alignment.
    let mut buffer = [0u8; MAX_RECORD + 16];
    match store.fetch_item::<&[u8]>(&mut buffer, &KEY).await {
        Ok(None) => {
            info!(
                "parameters: none stored in the {=u32} pages at {=u32:#x}, running with the defaults",
                STORE_PAGES, STORE_START
            );
            (None, ParamsStatus::None)
        }
        Ok(Some(record)) => match DriveParameters::decode(record) {
            Ok(parameters) => {
                info!("parameters: stored record read (version {=u8}, CRC ok)", record[3]);
                (Some(parameters), ParamsStatus::Stored)
            }
            Err(e) => {
                warn!("parameters: stored record refused ({=str}): running with the defaults", record_error(e));
                (None, ParamsStatus::Refused(e))
            }
        },
        Err(e) => {
            warn!("parameters: the store cannot be read ({}): running with the defaults", e);
            (None, ParamsStatus::Unreadable)
        }
    }
}

fn record_error(e: RecordError) -> &'static str {
    match e {
        RecordError::Truncated => "truncated",
        RecordError::Magic => "not a parameter record",
        RecordError::Version(_) => "written by another firmware version",
        RecordError::Crc => "CRC mismatch, corrupted",
        RecordError::Content => "invalid content",
    }
}
