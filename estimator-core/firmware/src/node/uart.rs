//! The board's UART0, polled: Arm's CMSDK APB UART, which QEMU's `mps2-an386` models at
//! 0x4000_4000 and connects to its first `-serial` (Arm DDI 0479, "APB UART"). The only
//! target-specific part of the sensor node besides the clock, which it does not use: a real
//! board changes this file (base address, baud divisor, or its HAL's serial driver).

use core::ptr::{read_volatile, write_volatile};

const BASE: usize = 0x4000_4000;
const DATA: *mut u32 = BASE as *mut u32;
const STATE: *mut u32 = (BASE + 0x04) as *mut u32;
const CTRL: *mut u32 = (BASE + 0x08) as *mut u32;
const BAUDDIV: *mut u32 = (BASE + 0x10) as *mut u32;

const STATE_TX_FULL: u32 = 1 << 0;
const STATE_RX_FULL: u32 = 1 << 1;
const CTRL_TX_EN: u32 = 1 << 0;
const CTRL_RX_EN: u32 = 1 << 1;

/// 25 MHz / 115 200 baud on the MPS2's AN386 image (QEMU does not time the line, a board
/// does).
const DIVISOR: u32 = 217;

/// UART0, enabled for transmit and receive, polled (no interrupts).
#[derive(Debug)]
pub struct Uart(());

impl Uart {
    /// Enables UART0.
    pub fn init() -> Self {
        // SAFETY: UART0's registers on this board; nothing else in the program touches them.
        unsafe {
            write_volatile(BAUDDIV, DIVISOR);
            write_volatile(CTRL, CTRL_TX_EN | CTRL_RX_EN);
        }
        Self(())
    }

    /// Waits for the next received byte.
    pub fn read(&self) -> u8 {
        loop {
            // SAFETY: as in `init`; reading DATA with RX full takes the byte.
            unsafe {
                if read_volatile(STATE) & STATE_RX_FULL != 0 {
                    return read_volatile(DATA) as u8;
                }
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
