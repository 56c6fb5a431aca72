//! `channel-sim`: simulates a plant, its sensors and the channel, and publishes the slots.

fn main() {
    eprintln!("channel-sim: the publisher arrives with the pipeline issue");
    std::process::exit(2);
}
