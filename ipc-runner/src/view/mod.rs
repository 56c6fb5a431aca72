//! The live view (docs/view.md): `run --view` and `demo --view` serve one page on loopback
//! that plots, while the run goes on, every estimator's x̂ with a ±2σ band against the truth,
//! a strip per sensor node (delivered / dropped / lost / late) and the end-to-end latency
//! (p50/p99 over the newest 1000 instants).
//!
//! The parts: [`tap`] (the loop's non-blocking queue; always built), and with the `view`
//! feature `feed` (the reader of the tap), `decimate`, `hub` (the frames to the
//! pages), `server` (HTTP and the websocket) and `assets` (the embedded page).

pub mod tap;

#[cfg(feature = "view")]
pub mod assets;
#[cfg(feature = "view")]
pub mod decimate;
#[cfg(feature = "view")]
pub mod feed;
#[cfg(feature = "view")]
pub mod hub;
#[cfg(feature = "view")]
pub mod server;

pub use tap::{EstimateEvent, ViewEvent, ViewTap};

/// Events the loop may be ahead of the view before the tap drops: an instant is one event per
/// estimator and one of its own (about 1 s at 1 kHz with 15 estimators).
pub const TAP_QUEUE: usize = 16384;

/// The view's options of `run` and `demo`.
#[derive(Clone, Debug, clap::Args)]
pub struct ViewArgs {
    /// Serve the live view (a page plotting the estimates as they come) on `--view-addr`.
    #[cfg(feature = "view")]
    #[arg(long)]
    pub view: bool,
    /// Address of the live view (loopback by default; port 0: any free port, printed).
    #[cfg(feature = "view")]
    #[arg(long, value_name = "ADDR", default_value = "127.0.0.1:8750")]
    pub view_addr: std::net::SocketAddr,
    /// After the run, keep serving the view (it says "run ended") this many seconds, or until
    /// SIGINT/SIGTERM.
    #[cfg(feature = "view")]
    #[arg(long, value_name = "SECONDS", default_value_t = 0.0,
          value_parser = estpipe_process::flags::seconds)]
    pub view_linger: f64,
    /// Points per series and second the view sends at most (decimated on the server, the
    /// newest always kept); a faster stream is thinned evenly.
    #[cfg(feature = "view")]
    #[arg(long, value_name = "N", default_value_t = 200,
          value_parser = clap::value_parser!(u32).range(1..=100_000))]
    pub view_points_per_s: u32,
}

// Derivable without the `view` feature (no fields), not with it.
#[allow(clippy::derivable_impls)]
impl Default for ViewArgs {
    fn default() -> Self {
        Self {
            #[cfg(feature = "view")]
            view: false,
            #[cfg(feature = "view")]
            view_addr: std::net::SocketAddr::from(([127, 0, 0, 1], 8750)),
            #[cfg(feature = "view")]
            view_linger: 0.0,
            #[cfg(feature = "view")]
            view_points_per_s: 200,
        }
    }
}

/// A running view: its tap for the loop.
#[derive(Debug, Default)]
pub struct View {
    tap: ViewTap,
    #[cfg_attr(not(feature = "view"), allow(dead_code))]
    linger: f64,
}

impl View {
    /// Starts the view when `args` ask for it (prints its address on stderr); an address that
    /// cannot be bound is an error before the run starts.
    pub fn start(args: &ViewArgs) -> anyhow::Result<Self> {
        #[cfg(feature = "view")]
        if args.view {
            let hub = std::sync::Arc::new(hub::Hub::default());
            let addr = server::start(args.view_addr, std::sync::Arc::clone(&hub))?;
            let (tx, rx) = std::sync::mpsc::sync_channel(TAP_QUEUE);
            let rate = args.view_points_per_s;
            std::thread::Builder::new()
                .name("view-feed".into())
                .spawn(move || feed::run(rx, hub, rate))?;
            estpipe_process::errln!("view: http://{addr}/");
            return Ok(Self {
                tap: ViewTap::new(tx),
                linger: args.view_linger,
            });
        }
        let _ = args;
        Ok(Self::default())
    }

    /// The loop's tap (empty without a view).
    pub fn tap(&self) -> ViewTap {
        self.tap.clone()
    }

    /// The run ended: the page says so; the view keeps serving `--view-linger` seconds (or
    /// until SIGINT/SIGTERM/SIGHUP).
    pub fn end(&self) {
        if !self.tap.is_on() {
            return;
        }
        self.tap.ended();
        #[cfg(feature = "view")]
        if self.linger > 0.0 {
            estpipe_process::errln!(
                "view: the run ended; serving the page {} s more (Ctrl-C to stop)",
                self.linger
            );
            let until = std::time::Instant::now() + std::time::Duration::from_secs_f64(self.linger);
            while std::time::Instant::now() < until
                && !estpipe_process::signal::termination_requested()
            {
                std::thread::sleep(std::time::Duration::from_millis(50));
            }
        }
    }
}
