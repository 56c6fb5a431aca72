//! The sensor node: reads each instant's raw sample from UART0 (fed by the gateway, standing in
//! for the ADC), decides with estimator-core's protocols whether to transmit it
//! (`estpipe_sensor_node::SensorNode`), and writes the decision back as a frame
//! (docs/sensor-node.md). Runs until the gateway's `Finish`, answers with its counters (its
//! stack peak included) and ends the emulation over semihosting.
//!
//! The step marker (`run::mark`) splits each sample's work for the instruction-count plugin:
//! `(n, BEGIN)` when the n-th frame's delimiter arrived (the interval before it is waiting for
//! input, not counted), then `(k, 1)` decoded, `(k, 2)` decided, `(k, 3)` answer encoded,
//! `(k, 4)` answer transmitted.
#![no_std]
#![no_main]

mod uart;

use estimator_firmware::run::mark::{step_mark, BEGIN};
use estimator_firmware::{exit, paint_stack, stack_peak, EXIT_OK};
use estpipe_sensor_node::{Deframer, Phase, Push, Reply, SensorNode, DELIMITER, MAX_FRAME};

/// Marker codes of the parts of one sample.
const DECODED: u8 = 1;
const DECIDED: u8 = 2;
const ENCODED: u8 = 3;
const SENT: u8 = 4;

#[cortex_m_rt::entry]
fn main() -> ! {
    paint_stack();
    let uart = uart::Uart::init();
    let mut node = SensorNode::new();
    let mut deframer = Deframer::new();
    let mut out = [0u8; MAX_FRAME];
    step_mark(0, 0);
    // Ends whatever a gateway's receiver had half received before this node started.
    uart.write(&[DELIMITER]);
    let mut frames: u32 = 0;
    loop {
        let byte = uart.read();
        let frame = match deframer.push(byte) {
            Push::More => continue,
            Push::Overlong => {
                node.count_bad_frame();
                continue;
            }
            Push::Frame(f) => f,
        };
        frames = frames.wrapping_add(1);
        step_mark(frames, BEGIN);
        let mut k = None;
        let reply = node.handle(frame, &mut out, |p| match p {
            Phase::Decoded(at) => {
                k = Some(at);
                step_mark(at, DECODED);
            }
            Phase::Decided(at) => step_mark(at, DECIDED),
            Phase::Encoded(at) => step_mark(at, ENCODED),
        });
        match reply {
            Reply::Nothing => {}
            Reply::Send(n) => {
                uart.write(&out[..n]);
                if let Some(k) = k {
                    step_mark(k, SENT);
                }
            }
            Reply::Finish => {
                let (peak, _) = stack_peak();
                let peak = u32::try_from(peak).unwrap_or(u32::MAX);
                if let Some(n) = node.finish(peak, &mut out) {
                    uart.write(&out[..n]);
                }
                exit(EXIT_OK);
            }
        }
    }
}
