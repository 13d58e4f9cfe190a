//! Emulated flash for the parameter store: [`SIZE`] bytes in RAM, laid out
//! as the firmware's store on the G474 (pages of [`PAGE`] bytes erased to
//! 0xFF, written a double word at a time, a double word written only once
//! between erases), kept in the file [`FILE`] of QEMU's working directory
//! through semihosting: read at start-up (absent: erased), written back
//! whole after every erase and write. A power cycle of the emulated chip is
//! QEMU started again in the same directory.
#![allow(unsafe_code)]

use cortex_m_semihosting::nr;
use embedded_storage_async::nor_flash::{ErrorType, NorFlash, NorFlashError, NorFlashErrorKind, ReadNorFlash};

/// Bytes of the store (the firmware's: the last 16 KiB of the G474's flash).
pub const SIZE: usize = 16 * 1024;
/// Erase page, bytes.
pub const PAGE: usize = 4096;
/// Program unit (a double word), bytes.
pub const WORD: usize = 8;
/// The backing file, NUL-terminated for the semihosting call.
pub const FILE: &[u8] = b"pil-flash.bin\0";

/// What went wrong with the emulated flash.
#[derive(Clone, Copy, Debug, PartialEq, Eq, defmt::Format)]
pub enum FlashError {
    /// Outside the store, or not aligned to a page (erase) or double word (write).
    OutOfBounds,
    /// A write to a double word that is not erased (the chip's PROGERR).
    NotErased,
    /// The backing file could not be written.
    File,
}

impl NorFlashError for FlashError {
    fn kind(&self) -> NorFlashErrorKind {
        match self {
            FlashError::OutOfBounds => NorFlashErrorKind::OutOfBounds,
            FlashError::NotErased | FlashError::File => NorFlashErrorKind::Other,
        }
    }
}

/// The emulated flash.
pub struct Flash {
    bytes: [u8; SIZE],
}

/// Calls semihosting operation `nr` with `args`.
fn call<const N: usize>(nr: usize, args: &[usize; N]) -> usize {
    // SAFETY: every call below passes the argument block its operation
    // expects (a NUL-terminated name and its length, or a handle, a buffer
    // that lives across the call and its length); QEMU runs with
    // semihosting enabled (`-semihosting-config enable=on`).
    unsafe { cortex_m_semihosting::syscall(nr, args) }
}

impl Flash {
    /// The flash as the backing file left it (erased if there is none, or
    /// if it cannot be read whole).
    pub fn load() -> Self {
        let mut flash = Self { bytes: [0xFF; SIZE] };
        let handle = call(nr::OPEN, &[FILE.as_ptr() as usize, nr::open::R_BINARY, FILE.len() - 1]);
        if handle == usize::MAX {
            return flash;
        }
        let mut image = [0xFFu8; SIZE];
        let unread = call(nr::READ, &[handle, image.as_mut_ptr() as usize, SIZE]);
        call(nr::CLOSE, &[handle]);
        if unread == 0 {
            flash.bytes = image;
        } else {
            defmt::warn!("flash: {} is {=usize} bytes short: taken as erased", defmt::Debug2Format(&FILE), unread);
        }
        flash
    }

    fn persist(&self) -> Result<(), FlashError> {
        let handle = call(nr::OPEN, &[FILE.as_ptr() as usize, nr::open::W_TRUNC_BINARY, FILE.len() - 1]);
        if handle == usize::MAX {
            return Err(FlashError::File);
        }
        let unwritten = call(nr::WRITE, &[handle, self.bytes.as_ptr() as usize, SIZE]);
        call(nr::CLOSE, &[handle]);
        if unwritten == 0 {
            Ok(())
        } else {
            Err(FlashError::File)
        }
    }
}

impl ErrorType for Flash {
    type Error = FlashError;
}

impl ReadNorFlash for Flash {
    const READ_SIZE: usize = 1;

    async fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), FlashError> {
        let start = offset as usize;
        let source = self.bytes.get(start..start + bytes.len()).ok_or(FlashError::OutOfBounds)?;
        bytes.copy_from_slice(source);
        Ok(())
    }

    fn capacity(&self) -> usize {
        SIZE
    }
}

impl NorFlash for Flash {
    const WRITE_SIZE: usize = WORD;
    const ERASE_SIZE: usize = PAGE;

    async fn erase(&mut self, from: u32, to: u32) -> Result<(), FlashError> {
        let (from, to) = (from as usize, to as usize);
        if from > to || to > SIZE || from % PAGE != 0 || to % PAGE != 0 {
            return Err(FlashError::OutOfBounds);
        }
        self.bytes[from..to].fill(0xFF);
        self.persist()
    }

    async fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), FlashError> {
        let start = offset as usize;
        if start % WORD != 0 || bytes.len() % WORD != 0 || start + bytes.len() > SIZE {
            return Err(FlashError::OutOfBounds);
        }
        let target = &mut self.bytes[start..start + bytes.len()];
        if target.iter().any(|&b| b != 0xFF) {
            return Err(FlashError::NotErased);
        }
        target.copy_from_slice(bytes);
        self.persist()
    }
}
