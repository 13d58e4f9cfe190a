//! The CMSDK APB UARTs of the MPS2 board (as QEMU emulates them), polled:
//! UART0 (0x4000_4000) carries the PIL frames, UART1 (0x4000_5000) the DCP
//! line of the lift controller, UART2 (0x4000_6000) the service port.
//!
//! Registers from the base: DATA (+0x00), STATE (+0x04: bit 0 TX full,
//! bit 1 RX full), CTRL (+0x08: bit 0 TX enable, bit 1 RX enable, bit 3 RX
//! interrupt enable), INTCLEAR (+0x0C: bit 1 clears the RX interrupt),
//! BAUDDIV (+0x10, at least 16 for the UART to run).
//!
//! Waiting for a byte sleeps in `wfi` on the RX interrupt (IRQ 0 of the
//! MPS2) with interrupts masked (PRIMASK), so the pending interrupt only wakes
//! the core: no handler runs. A busy poll would keep the emulated core
//! spinning on the register and starve the emulator's I/O thread.
#![allow(unsafe_code)]

const BASE: usize = 0x4000_4000;
const DATA: usize = BASE;
const STATE: usize = BASE + 0x04;
const CTRL: usize = BASE + 0x08;
const INTCLEAR: usize = BASE + 0x0C;
const BAUDDIV: usize = BASE + 0x10;
/// UART1's registers: UART0's, 0x1000 further.
const UART1_OFFSET: usize = 0x1000;
/// UART2's registers: UART0's, 0x2000 further.
const UART2_OFFSET: usize = 0x2000;
/// NVIC interrupt number of the UART0 receiver on the MPS2.
const UART0_RX_IRQ: u32 = 0;
const NVIC_ISER0: usize = 0xE000_E100;
const NVIC_ICPR0: usize = 0xE000_E280;
const TX_FULL: u32 = 1 << 0;
const RX_FULL: u32 = 1 << 1;

fn read(address: usize) -> u32 {
    // SAFETY: `address` is one of the UART registers above, a valid,
    // aligned MMIO location on this machine; volatile keeps every access.
    unsafe { core::ptr::read_volatile(address as *const u32) }
}

fn write(address: usize, value: u32) {
    // SAFETY: as in `read`; writes to these registers have no effect on
    // memory the program uses.
    unsafe { core::ptr::write_volatile(address as *mut u32, value) }
}

/// UART0, polled. Only one exists; `main` creates it once.
pub struct Uart0(());

impl Uart0 {
    /// Sets the baud divider and enables transmitter and receiver.
    pub fn enable() -> Self {
        cortex_m::interrupt::disable();
        write(BAUDDIV, 16);
        write(CTRL, 0b1011);
        write(NVIC_ISER0, 1 << UART0_RX_IRQ);
        Self(())
    }

    /// Waits (asleep) for and returns the next received byte.
    pub fn read_byte(&mut self) -> u8 {
        while read(STATE) & RX_FULL == 0 {
            cortex_m::asm::wfi();
            write(INTCLEAR, RX_FULL);
            write(NVIC_ICPR0, 1 << UART0_RX_IRQ);
        }
        read(DATA) as u8
    }

    /// Sends `bytes`, waiting whenever the transmit buffer is full.
    pub fn write_all(&mut self, bytes: &[u8]) {
        for &byte in bytes {
            while read(STATE) & TX_FULL != 0 {}
            write(DATA, byte as u32);
        }
    }
}

/// A UART polled without interrupts: UART1 (the DCP line) or UART2 (the service port).
pub struct Polled {
    offset: usize,
}

impl Polled {
    /// UART1, the DCP line: sets the baud divider and enables transmitter
    /// and receiver (no interrupt). `main` creates it once.
    pub fn uart1() -> Self {
        Self::enable(UART1_OFFSET)
    }

    /// UART2, the service port, likewise.
    pub fn uart2() -> Self {
        Self::enable(UART2_OFFSET)
    }

    fn enable(offset: usize) -> Self {
        write(BAUDDIV + offset, 16);
        write(CTRL + offset, 0b0011);
        Self { offset }
    }

    /// The received byte, if one is waiting.
    pub fn try_read_byte(&mut self) -> Option<u8> {
        if read(STATE + self.offset) & RX_FULL == 0 {
            return None;
        }
        Some(read(DATA + self.offset) as u8)
    }

    /// Sends `bytes`, waiting whenever the transmit buffer is full.
    pub fn write_all(&mut self, bytes: &[u8]) {
        for &byte in bytes {
            while read(STATE + self.offset) & TX_FULL != 0 {}
            write(DATA + self.offset, byte as u32);
        }
    }
}
