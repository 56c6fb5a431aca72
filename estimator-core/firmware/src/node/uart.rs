//! The board's UART0: Arm's CMSDK APB UART, which QEMU's `mps2-an386` models at 0x4000_4000
//! and connects to its first `-serial` (Arm DDI 0479, "APB UART"). The only target-specific
//! part of the sensor node besides the clock, which it does not use: a real board changes
//! this file (base address, IRQ, baud divisor, or its HAL's serial driver).
//!
//! Receiving sleeps: with interrupts masked (PRIMASK), the UART's receive interrupt pends in
//! the NVIC and wakes `wfi` without being taken (Armv7-M ARM, B1.5.19), so an idle node costs
//! its host no CPU (three spinning QEMUs on two cores slowed the loop thirtyfold).

use core::ptr::{read_volatile, write_volatile};

const BASE: usize = 0x4000_4000;
const DATA: *mut u32 = BASE as *mut u32;
const STATE: *mut u32 = (BASE + 0x04) as *mut u32;
const CTRL: *mut u32 = (BASE + 0x08) as *mut u32;
const INTCLEAR: *mut u32 = (BASE + 0x0C) as *mut u32;
const BAUDDIV: *mut u32 = (BASE + 0x10) as *mut u32;
/// NVIC interrupt set-enable and clear-pending registers 0 (IRQs 0-31).
const NVIC_ISER0: *mut u32 = 0xE000_E100 as *mut u32;
const NVIC_ICPR0: *mut u32 = 0xE000_E280 as *mut u32;
/// UART0's receive interrupt on the AN386 image.
const UART0_RX_IRQ: u32 = 0;

const STATE_TX_FULL: u32 = 1 << 0;
const STATE_RX_FULL: u32 = 1 << 1;
const CTRL_TX_EN: u32 = 1 << 0;
const CTRL_RX_EN: u32 = 1 << 1;
const CTRL_RX_INT_EN: u32 = 1 << 3;
const INT_RX: u32 = 1 << 1;

/// 25 MHz / 115 200 baud on the MPS2's AN386 image (QEMU does not time the line, a board
/// does).
const DIVISOR: u32 = 217;

/// UART0, enabled for transmit and receive, polled (no interrupts).
#[derive(Debug)]
pub struct Uart(());

impl Uart {
    /// Enables UART0 and its receive interrupt as a wake-up source (masked: never taken).
    pub fn init() -> Self {
        // SAFETY: UART0's and the NVIC's registers on this board; nothing else in the program
        // touches them, and with PRIMASK set no handler runs.
        unsafe {
            core::arch::asm!("cpsid i", options(nomem, nostack, preserves_flags));
            write_volatile(BAUDDIV, DIVISOR);
            write_volatile(CTRL, CTRL_TX_EN | CTRL_RX_EN | CTRL_RX_INT_EN);
            write_volatile(NVIC_ISER0, 1 << UART0_RX_IRQ);
        }
        Self(())
    }

    /// Waits (asleep) for the next received byte.
    pub fn read(&self) -> u8 {
        loop {
            // SAFETY: as in `init`; reading DATA with RX full takes the byte. The interrupt
            // is cleared at the UART first, then in the NVIC (a level source would pend
            // again otherwise); RX full is tested before every sleep, so a byte that arrives
            // in between is never slept on.
            unsafe {
                if read_volatile(STATE) & STATE_RX_FULL != 0 {
                    let b = read_volatile(DATA) as u8;
                    write_volatile(INTCLEAR, INT_RX);
                    write_volatile(NVIC_ICPR0, 1 << UART0_RX_IRQ);
                    return b;
                }
                core::arch::asm!("wfi", options(nomem, nostack, preserves_flags));
            }
        }
    }

    /// Transmits `bytes`, each once the transmit buffer has room.
    pub fn write(&self, bytes: &[u8]) {
        for &b in bytes {
            // SAFETY: as in `init`.
            unsafe {
                while read_volatile(STATE) & STATE_TX_FULL != 0 {}
                write_volatile(DATA, u32::from(b));
            }
        }
    }
}
