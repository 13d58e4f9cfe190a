//! The drive's parameters in flash: one `drive_core::param_store` record
//! (strategy, harmonic table, car mass, encoder offset; versioned,
//! CRC-32 checked) kept under key 0 of a `sequential-storage` map, which
//! spreads the writes over [`STORE_PAGES`] flash pages (wear levelling) and
//! survives a power loss during a write (the previous record stays).
//!
//! Where: the last 16 KiB of the 512 KiB flash, eight 2 KiB pages of bank 2
//! in the factory dual-bank layout (RM0440, embedded flash: 2 KiB pages in
//! dual-bank mode; embassy-stm32's G474 flash data, erase size 2048), so
//! erasing and writing it does not stall code running from bank 1
//! (read-while-write); `memory.x` holds the program to bank 1, the first
//! 256 KiB.
//!
//! A record that fails any check (magic, version, length, CRC, values) is
//! refused whole: the drive runs with its defaults and the log says why.
//!
//! Writing (the service port's `save`): the flash driver used here
//! (`Flash::blocking_erase`/`blocking_write` of embassy-stm32) does not mask
//! interrupts; the erase (22-40 ms a page on the G4) and the programming
//! block the thread-mode executor, not the interrupts, which keep running
//! from bank 1 (the UARTs keep receiving). The service task writes only
//! with the drive idle or waiting for its alignment, with the control
//! interrupt paused (`control::pause_if_idle`: inverter off and brake
//! applied throughout), then resumes it without counting the pause as a
//! missed deadline. Untested on the board: the blocked executor must hand
//! back within the independent watchdog's ~100 ms (the telemetry task
//! feeds it).

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
/// Flash page size in the dual-bank layout, bytes (RM0440: 2 KiB).
pub const PAGE_BYTES: u32 = 2048;
/// Flash pages of the store (2 KiB each): 8.
pub const STORE_PAGES: u32 = (STORE_END - STORE_START) / PAGE_BYTES;

// The store must lie in bank 2 (from 512 KiB / 2), whole pages, and match the
// driver's erase size.
const _: () = {
    assert!(STORE_START >= 0x4_0000 && STORE_START % PAGE_BYTES == 0 && STORE_END % PAGE_BYTES == 0);
    assert!(embassy_stm32::flash::FLASH_SIZE as u32 == STORE_END);
};

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
