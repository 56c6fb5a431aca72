//! The page of the live view, embedded in the executable (docs/view.md): `ipc-runner/view/`
//! (the page and its script) and the vendored uPlot 1.6.32 with its MIT licence
//! (`ipc-runner/view/vendor/uplot/`); nothing is fetched from the network.

/// `(path, content type, body)` of every asset the server answers.
pub const ASSETS: &[(&str, &str, &[u8])] = &[
    (
        "/",
        "text/html; charset=utf-8",
        include_bytes!("../../view/index.html"),
    ),
    (
        "/view.js",
        "text/javascript; charset=utf-8",
        include_bytes!("../../view/view.js"),
    ),
    (
        "/uPlot.iife.min.js",
        "text/javascript; charset=utf-8",
        include_bytes!("../../view/vendor/uplot/uPlot.iife.min.js"),
    ),
    (
        "/uPlot.min.css",
        "text/css; charset=utf-8",
        include_bytes!("../../view/vendor/uplot/uPlot.min.css"),
    ),
    (
        "/uPlot-LICENSE.txt",
        "text/plain; charset=utf-8",
        include_bytes!("../../view/vendor/uplot/LICENSE"),
    ),
];
