//! Spec files from outside the process are hostile: the shipped examples load, and every bad
//! field is refused with one line naming the file and the field, never a panic, a hang or an
//! unbounded read.

use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use estpipe_spec::file::{load, parse, MAX_FILE_BYTES};
use estpipe_spec::SpecError;

#[path = "../../tests/skip_log.rs"]
mod skip_log;

const LINEAR: &str = include_str!("../../specs/linear.toml");
const OCCLUSION: &str = include_str!("../../specs/occlusion.toml");
/// The origin every case is parsed under: errors must name it.
const ORIGIN: &str = "/hostile/dir/case.toml";

fn specs_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../specs")
}

fn scratch() -> PathBuf {
    let d = std::env::temp_dir().join(format!("estpipe-spec-file-tests-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// `base` with the first `from` replaced by `to` (`from` must be there).
fn edit(base: &str, from: &str, to: &str) -> String {
    assert!(base.contains(from), "base has no {from:?}");
    base.replacen(from, to, 1)
}

/// The linear example with a second sensor of ny = 2 (for per-node checks).
fn two_sensors() -> String {
    format!("{LINEAR}\n[[sensors]]\nc = [[1.0, 0.0], [0.0, 1.0]]\nr = [[0.5, 0.0], [0.0, 0.5]]\n")
}

/// An `[event_trigger]` table with `nodes` nodes, each with `reference` and `lambda`.
fn trigger(nodes: usize, reference: &str, lambda: f64, opt_in: bool) -> String {
    let mut s = format!(
        "\n[event_trigger]\ninitial_tokens = 3\nrate = 2\ncapacity = 6\n\
         allow_paper_violation = {opt_in}\n"
    );
    for _ in 0..nodes {
        s += &format!(
            "[[event_trigger.nodes]]\nsigma = 0.5\nchi = 5.0\nlambda = {lambda}\neta0 = 1.0\n\
             reference = {reference}\ncost = 1\n"
        );
    }
    s
}

fn occlusion(body: &str) -> String {
    format!("{LINEAR}\n[occlusion]\n{body}\n")
}

fn token_bucket(a: &str, b: &str, s: &str, z0: &str) -> String {
    format!("{LINEAR}\n[token_bucket]\na = {a}\nb = {b}\ns = {s}\nz0 = {z0}\n")
}

/// What an error must name.
#[derive(Clone, Copy, Debug)]
enum Names {
    /// A validated field: the message holds "invalid `FIELD`:".
    Field(&'static str),
    /// A parser error: the message holds the line and this text (a key, an unknown name).
    Parser(&'static str),
}

/// (case, text, what its error must name).
fn cases() -> Vec<(&'static str, String, Names)> {
    use Names::{Field, Parser};
    let lin = |from: &str, to: &str| edit(LINEAR, from, to);
    let occ = |from: &str, to: &str| edit(OCCLUSION, from, to);
    let plus = |extra: &str| format!("{LINEAR}{extra}");
    let top = |key: &str| format!("{key}\n{LINEAR}");
    let a = "a = [[0.95, 0.10], [-0.10, 0.95]]";
    let b = "b = [[1.0, 0.0], [0.0, 1.0]]";
    let q = "q = [[0.01, 0.0], [0.0, 0.04]]";
    let c = "c = [[1.0, 0.0]]";
    let d = "d = [[1.0]]";
    let r = "r = [[0.25]]";
    let mean = "mean = [0.0, 0.0]";
    let cov = "cov = [[1.0, 0.0], [0.0, 1.0]]";
    let nine_rows = |row: &str| format!("[{}]", [row; 9].join(", "));
    vec![
        // Matrix sizes.
        ("A of one row", lin(a, "a = [[0.95, 0.10]]"), Field("model.a")),
        ("A ragged", lin(a, "a = [[0.95, 0.10], [1.0]]"), Field("model.a")),
        ("A empty", lin(a, "a = []"), Field("model.a")),
        ("A of empty rows", lin(a, "a = [[], []]"), Field("model.a")),
        ("A 9×9", lin(a, &format!("a = {}", nine_rows(&format!("[{}]", ["0.1"; 9].join(", "))))), Field("model.a")),
        ("B of one row", lin(b, "b = [[1.0, 0.0]]"), Field("model.b")),
        ("B with a column fewer than Q", lin(b, "b = [[1.0], [0.0]]"), Field("model.b")),
        ("B ragged", lin(b, "b = [[1.0, 0.0], [0.0]]"), Field("model.b")),
        ("C with 3 columns", lin(c, "c = [[1.0, 0.0, 0.0]]"), Field("sensors[0].c")),
        ("C with 1 column", lin(c, "c = [[1.0]]"), Field("sensors[0].c")),
        ("C with 5 rows (ny > 4)", lin(c, &format!("c = [{}]", ["[1.0, 0.0]"; 5].join(", "))), Field("sensors[0].c")),
        ("D with 2 columns for a 1×1 R", lin(d, "d = [[1.0, 0.0]]"), Field("sensors[0].d")),
        ("D with 2 rows for ny 1", lin(d, "d = [[1.0], [0.0]]"), Field("sensors[0].d")),
        ("R of the wrong size for D", lin(r, "r = [[0.25, 0.0], [0.0, 0.25]]"), Field("sensors[0].d")),
        ("no sensors", LINEAR.split("[[sensors]]").next().unwrap().to_owned(), Parser("sensors")),
        ("an empty sensor list", format!("sensors = []\n{}", LINEAR.split("[[sensors]]").next().unwrap()), Field("sensors")),
        ("9 sensors", format!("{LINEAR}{}", "\n[[sensors]]\nc = [[1.0, 0.0]]\nr = [[1.0]]\n".repeat(8)), Field("sensors")),
        ("prior.mean of 1", lin(mean, "mean = [0.0]"), Field("prior.mean")),
        ("prior.mean of 3", lin(mean, "mean = [0.0, 0.0, 0.0]"), Field("prior.mean")),
        ("prior.cov 1×1", lin(cov, "cov = [[1.0]]"), Field("prior.cov")),
        ("prior.cov 3×3", lin(cov, "cov = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]"), Field("prior.cov")),
        ("prior.cov 2×3", lin(cov, "cov = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]"), Field("prior.cov")),
        ("prior.cov 1×2", lin(cov, "cov = [[1.0, 0.0]]"), Field("prior.cov")),
        // Covariances that are not positive definite (or not symmetric).
        ("Q indefinite", lin(q, "q = [[0.01, 0.0], [0.0, -0.04]]"), Field("model.q")),
        ("Q not symmetric", lin(q, "q = [[0.01, 0.5], [0.0, 0.04]]"), Field("model.q")),
        ("Q zero", lin(q, "q = [[0.0, 0.0], [0.0, 0.0]]"), Field("model.q")),
        ("R zero", lin(r, "r = [[0.0]]"), Field("sensors[0].r")),
        ("R negative", lin(r, "r = [[-0.25]]"), Field("sensors[0].r")),
        ("prior.cov indefinite", lin(cov, "cov = [[1.0, 2.0], [2.0, 1.0]]"), Field("prior.cov")),
        ("prior.cov not symmetric", lin(cov, "cov = [[1.0, 0.5], [0.0, 1.0]]"), Field("prior.cov")),
        // NaN and ±∞.
        ("nan in A", lin(a, "a = [[nan, 0.10], [-0.10, 0.95]]"), Field("model.a")),
        ("inf in B", lin(b, "b = [[inf, 0.0], [0.0, 1.0]]"), Field("model.b")),
        ("-inf in Q", lin(q, "q = [[-inf, 0.0], [0.0, 0.04]]"), Field("model.q")),
        ("nan in C", lin(c, "c = [[nan, 0.0]]"), Field("sensors[0].c")),
        ("inf in D", lin(d, "d = [[inf]]"), Field("sensors[0].d")),
        ("inf in R", lin(r, "r = [[inf]]"), Field("sensors[0].r")),
        ("nan in the prior mean", lin(mean, "mean = [nan, 0.0]"), Field("prior.mean")),
        ("inf in the prior cov", lin(cov, "cov = [[inf, 0.0], [0.0, 1.0]]"), Field("prior.cov")),
        // Finite numbers whose products overflow: the overflow check names the field.
        ("1e308 in A", lin(a, "a = [[1e308, 0.10], [-0.10, 0.95]]"), Field("model.a")),
        ("1e200 in A", lin(a, "a = [[1e200, 0.10], [-0.10, 0.95]]"), Field("model.a")),
        ("1e155 in B", lin(b, "b = [[1e155, 0.0], [0.0, 1.0]]"), Field("model.b")),
        ("1e308 in Q", lin(q, "q = [[1e308, 0.0], [0.0, 0.04]]"), Field("model.q")),
        ("1e308 in C", lin(c, "c = [[1e308, 0.0]]"), Field("sensors[0].c")),
        ("1e160 in C", lin(c, "c = [[1e160, 0.0]]"), Field("sensors[0].c")),
        ("1e308 in R", lin(r, "r = [[1e308]]"), Field("sensors[0].r")),
        ("1e308 in the prior mean", lin(mean, "mean = [1e308, 0.0]"), Field("prior.mean")),
        ("prior cov 1e308·I", lin(cov, "cov = [[1e308, 0.0], [0.0, 1e308]]"), Field("prior.cov")),
        ("control u of 1e308", plus("\n[control]\nb = [[1.0], [0.0]]\nu = { kind = \"constant\", value = [1e308] }\n"), Field("control.u")),
        // Control input.
        ("control b with 3 rows", plus("\n[control]\nb = [[1.0], [0.0], [0.0]]\nu = { kind = \"constant\", value = [1.0] }\n"), Field("control.b")),
        ("control u of the wrong length", plus("\n[control]\nb = [[1.0], [0.0]]\nu = { kind = \"constant\", value = [1.0, 2.0] }\n"), Field("control.u.value")),
        ("control period 0", plus("\n[control]\nb = [[1.0], [0.0]]\nu = { kind = \"sinusoid\", amplitude = [1.0], period = 0.0 }\n"), Field("control.u.period")),
        ("control phase nan", plus("\n[control]\nb = [[1.0], [0.0]]\nu = { kind = \"sinusoid\", amplitude = [1.0], period = 4.0, phase = nan }\n"), Field("control.u.phase")),
        ("control offset length", plus("\n[control]\nb = [[1.0], [0.0]]\nu = { kind = \"sinusoid\", amplitude = [1.0], period = 4.0, offset = [0.0, 1.0] }\n"), Field("control.u.offset")),
        ("empty control list", plus("\n[control]\nb = [[1.0], [0.0]]\nu = { kind = \"list\", values = [] }\n"), Field("control.u.values")),
        ("control list entry length", plus("\n[control]\nb = [[1.0], [0.0]]\nu = { kind = \"list\", values = [[1.0], [1.0, 2.0]] }\n"), Field("control.u.values[1]")),
        ("unknown schedule", plus("\n[control]\nb = [[1.0], [0.0]]\nu = { kind = \"teleport\", value = [1.0] }\n"), Parser("teleport")),
        // Unknown keys and tables; simulation-only sections are unknown here.
        ("unknown top-level key", lin("name = \"linear\"", "nmae = \"linear\""), Parser("nmae")),
        ("unknown key in [model]", lin(q, &format!("{q}\nqq = 1.0")), Parser("qq")),
        ("unknown key in [prior]", lin(mean, &format!("{mean}\nestimator_mean = [0.0, 0.0]")), Parser("estimator_mean")),
        ("unknown key in [[sensors]]", lin(r, &format!("{r}\nrate = 2")), Parser("rate")),
        ("unknown table", plus("\n[plant]\nx = 1\n"), Parser("plant")),
        ("[initial] (simulation only)", plus("\n[initial]\nmean = [0.0, 0.0]\ncov = [[1.0, 0.0], [0.0, 1.0]]\n"), Parser("initial")),
        ("[[stages]] (simulation only)", plus("\n[[stages]]\nkind = \"bernoulli\"\np_loss = 0.1\n"), Parser("stages")),
        ("unknown key in [occlusion]", occlusion("e = [1.0, 0.0]\npsi = 0.1\ncentres = [1.0]\nradii = [0.5]\nkind = \"occlusion\""), Parser("kind")),
        ("a string for a number", lin(q, "q = \"small\""), Parser("q")),
        ("a string gate", top("gate = \"high\""), Parser("gate")),
        ("no [model]", lin("[model]", "[modle]"), Parser("modle")),
        ("missing prior", LINEAR.split("[prior]").next().unwrap().to_owned() + "[[sensors]]\nc = [[1.0, 0.0]]\nr = [[0.25]]\n", Parser("prior")),
        ("not TOML", "a = [[".to_owned(), Parser("line 1")),
        // Occlusion.
        ("psi 0", occ("psi = 0.1", "psi = 0.0"), Field("occlusion.psi")),
        ("psi negative", occ("psi = 0.1", "psi = -0.1"), Field("occlusion.psi")),
        ("psi 1e308", occ("psi = 0.1", "psi = 1e308"), Field("occlusion.psi")),
        ("psi nan", occ("psi = 0.1", "psi = nan"), Field("occlusion.psi")),
        ("psi inf", occ("psi = 0.1", "psi = inf"), Field("occlusion.psi")),
        ("overlapping regions", occ("centres = [20.0, 40.0, 60.0, 80.0]", "centres = [20.0, 25.0, 60.0, 80.0]"), Field("occlusion.regions")),
        ("overlapping regions at 1e308", occlusion("e = [1.0, 0.0]\npsi = 0.1\ncentres = [1e308, -1e308]\nradii = [1.5e308, 1.5e308]"), Field("occlusion.regions")),
        ("5 regions", occ("centres = [20.0, 40.0, 60.0, 80.0]", "centres = [20.0, 40.0, 60.0, 80.0, 100.0]").replace("radii = [5.0, 5.0, 5.0, 5.0]", "radii = [5.0, 5.0, 5.0, 5.0, 5.0]"), Field("occlusion.centres")),
        ("no regions", occlusion("e = [1.0, 0.0]\npsi = 0.1\ncentres = []\nradii = []"), Field("occlusion.centres")),
        ("more centres than radii", occ("radii = [5.0, 5.0, 5.0, 5.0]", "radii = [5.0, 5.0, 5.0]"), Field("occlusion.radii")),
        ("more radii than centres", occ("radii = [5.0, 5.0, 5.0, 5.0]", "radii = [5.0, 5.0, 5.0, 5.0, 5.0]"), Field("occlusion.radii")),
        ("negative radius", occ("radii = [5.0, 5.0, 5.0, 5.0]", "radii = [5.0, -5.0, 5.0, 5.0]"), Field("occlusion.regions")),
        ("nan centre", occ("centres = [20.0, 40.0, 60.0, 80.0]", "centres = [20.0, nan, 60.0, 80.0]"), Field("occlusion.regions")),
        ("e of 2 for nx 3", occ("e = [1.0, 0.0, 0.0]", "e = [1.0, 0.0]"), Field("occlusion.e")),
        ("e of 4 for nx 3", occ("e = [1.0, 0.0, 0.0]", "e = [1.0, 0.0, 0.0, 0.0]"), Field("occlusion.e")),
        ("nan in e", occ("e = [1.0, 0.0, 0.0]", "e = [nan, 0.0, 0.0]"), Field("occlusion.e")),
        // Token bucket (seed 003): a ≥ 1, b ≥ a, S ≥ b, z0 ≤ S.
        ("token bucket a = 0", token_bucket("0", "3", "10", "6"), Field("token_bucket.a")),
        ("token bucket a > b", token_bucket("4", "3", "10", "6"), Field("token_bucket.b")),
        ("token bucket s < b", token_bucket("2", "3", "2", "1"), Field("token_bucket.s")),
        ("token bucket z0 > s", token_bucket("2", "3", "10", "11"), Field("token_bucket.z0")),
        ("token bucket a negative", token_bucket("-1", "3", "10", "6"), Parser("a")),
        ("token bucket a too large", token_bucket("4294967296", "3", "10", "6"), Parser("a")),
        ("token bucket a missing", format!("{LINEAR}\n[token_bucket]\nb = 3\ns = 10\nz0 = 6\n"), Parser("a")),
        // Tobit: one threshold vector per node, one threshold per component.
        ("tobit for 2 nodes of 1", plus("\n[tobit]\nthresholds = [[0.0], [0.0]]\n"), Field("tobit.thresholds")),
        ("tobit for no node", plus("\n[tobit]\nthresholds = []\n"), Field("tobit.thresholds")),
        ("tobit thresholds of ny 2", plus("\n[tobit]\nthresholds = [[0.0, 1.0]]\n"), Field("tobit.thresholds[0]")),
        ("tobit thresholds empty", plus("\n[tobit]\nthresholds = [[]]\n"), Field("tobit.thresholds[0]")),
        ("tobit threshold nan", plus("\n[tobit]\nthresholds = [[nan]]\n"), Field("tobit.thresholds[0]")),
        ("tobit for the wrong node's ny", format!("{}\n[tobit]\nthresholds = [[0.0], [0.0]]\n", two_sensors()), Field("tobit.thresholds[1]")),
        ("tobit nodes swapped", format!("{}\n[tobit]\nthresholds = [[0.0, 0.0], [0.0]]\n", two_sensors()), Field("tobit.thresholds[0]")),
        // Event trigger (seed 004).
        ("trigger with 2 nodes of 1", plus(&trigger(2, "[0.0]", 0.5, false)), Field("event_trigger.nodes")),
        ("trigger with 1 node of 2", format!("{}{}", two_sensors(), trigger(1, "[0.0]", 0.5, false)), Field("event_trigger.nodes")),
        ("trigger with no node", plus(&trigger(0, "[0.0]", 0.5, false)), Parser("nodes")),
        ("trigger with an empty node list", plus("\n[event_trigger]\ninitial_tokens = 3\nrate = 2\ncapacity = 6\nnodes = []\n"), Field("event_trigger.nodes")),
        ("trigger reference of ny 2", plus(&trigger(1, "[0.0, 0.0]", 0.5, false)), Field("event_trigger.nodes[0].reference")),
        ("trigger reference empty", plus(&trigger(1, "[]", 0.5, false)), Field("event_trigger.nodes[0].reference")),
        ("trigger reference nan", plus(&trigger(1, "[nan]", 0.5, false)), Field("event_trigger.nodes[0].reference")),
        ("trigger λχ ≤ 1", plus(&trigger(1, "[0.0]", 0.1, false)), Field("event_trigger.nodes[0]")),
        ("trigger λ negative even with the opt-in", plus(&trigger(1, "[0.0]", -0.5, true)), Field("event_trigger.nodes[0]")),
        ("trigger initial tokens above capacity", plus(&trigger(1, "[0.0]", 0.5, false).replace("initial_tokens = 3", "initial_tokens = 7")), Field("event_trigger.initial_tokens")),
        ("trigger capacity 0", plus(&trigger(1, "[0.0]", 0.5, false).replace("initial_tokens = 3", "initial_tokens = 0").replace("capacity = 6", "capacity = 0")), Field("event_trigger.capacity")),
        ("trigger negative tokens", plus(&trigger(1, "[0.0]", 0.5, false).replace("initial_tokens = 3", "initial_tokens = -3")), Parser("initial_tokens")),
        // The runner's options.
        ("loss_rate negative", top("loss_rate = -0.1"), Field("loss_rate")),
        ("loss_rate 1", top("loss_rate = 1.0"), Field("loss_rate")),
        ("loss_rate nan", top("loss_rate = nan"), Field("loss_rate")),
        ("loss_rate inf", top("loss_rate = inf"), Field("loss_rate")),
        ("gate 0", top("gate = 0.0"), Field("gate")),
        ("gate 1", top("gate = 1.0"), Field("gate")),
        ("gate negative", top("gate = -0.5"), Field("gate")),
        ("gate nan", top("gate = nan"), Field("gate")),
        ("gate 1e308", top("gate = 1e308"), Field("gate")),
    ]
}

/// Why `err` is not one line naming [`ORIGIN`] and `names`, if it is not.
fn fault(err: &SpecError, names: Names) -> Option<String> {
    let e = err.to_string();
    if e.contains('\n') || e.contains('\r') {
        return Some(format!("not one line: {e:?}"));
    }
    if !matches!(err, SpecError::File { path, .. } if path == ORIGIN) || !e.starts_with(ORIGIN) {
        return Some(format!("origin not named first: {e}"));
    }
    match names {
        Names::Field(f) if !e.contains(&format!("invalid `{f}`:")) => {
            Some(format!("field `{f}` not named: {e}"))
        }
        Names::Parser(p) if !(e.contains(p) && e.contains("line ")) => {
            Some(format!("{p:?} or its line not named: {e}"))
        }
        _ => None,
    }
}

#[test]
fn the_shipped_specs_load() {
    let lin = load(&specs_dir().join("linear.toml")).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(lin.name, "linear");
    assert_eq!((lin.nx(), lin.nodes(), lin.ny()), (2, 1, 1));
    assert_eq!((lin.loss_rate, lin.gate), (None, None));
    let l = lin.linear().unwrap();
    assert_eq!(l.a()[(1, 0)], -0.10);
    assert_eq!(l.q()[(1, 1)], 0.04);
    assert_eq!(l.sensors()[0].r[(0, 0)], 0.25);
    assert!(l.control().is_none() && lin.channel == Default::default());
    assert!(lin.warnings().is_empty());

    let occ = load(&specs_dir().join("occlusion.toml")).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(occ.name, "occlusion");
    assert_eq!((occ.nx(), occ.nodes(), occ.ny()), (3, 1, 2));
    assert_eq!(occ.prior.mean.as_slice(), &[5.0, 5.0, 5.0]);
    let o = occ.channel.occlusion.as_ref().unwrap();
    assert_eq!(o.centres(), &[20.0, 40.0, 60.0, 80.0]);
    assert_eq!((o.count(), o.psi(), o.e()), (4, 0.1, &[1.0, 0.0, 0.0][..]));
    assert!(o.regions::<4>().is_ok() && o.at::<3, 4>().is_some());

    // Every .toml shipped in specs/ loads; the two above are among them.
    let mut n = 0;
    for entry in std::fs::read_dir(specs_dir()).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "toml") {
            load(&path).unwrap_or_else(|e| panic!("{e}"));
            n += 1;
        }
    }
    assert!(n >= 2);
}

#[test]
fn the_name_defaults_to_the_stem_and_the_options_are_read() {
    let text = edit(LINEAR, "name = \"linear\"\n", "");
    let spec = parse(&text, ORIGIN, "stem").unwrap();
    assert_eq!(spec.name, "stem");
    let spec = parse(
        &format!("loss_rate = 0.0\ngate = 0.99\n{LINEAR}"),
        ORIGIN,
        "x",
    )
    .unwrap();
    assert_eq!((spec.loss_rate, spec.gate), (Some(0.0), Some(0.99)));
    // Seed 004 knowledge on two nodes of different ny, and a token bucket.
    let text = format!(
        "{}\n[tobit]\nthresholds = [[0.5], [0.5, -1.0]]\n[token_bucket]\na = 2\nb = 3\ns = 10\nz0 = 6\n",
        two_sensors()
    );
    let spec = parse(&text, ORIGIN, "x").unwrap();
    assert_eq!(
        (spec.nodes(), spec.node_ny(0), spec.node_ny(1), spec.ny()),
        (2, 1, 2, 2)
    );
    let t = spec.channel.tobit.as_ref().unwrap();
    assert_eq!((t.tau(0), t.tau(1)), (&[0.5][..], &[0.5, -1.0][..]));
    let b = spec.channel.token_bucket.unwrap();
    assert_eq!((b.a, b.b, b.s, b.z0), (2, 3, 10, 6));
}

#[test]
fn the_event_trigger_opt_in_is_accepted_with_a_warning() {
    let ok = parse(
        &format!("{LINEAR}{}", trigger(1, "[0.0]", 0.5, false)),
        ORIGIN,
        "x",
    )
    .unwrap();
    assert!(ok.warnings().is_empty());
    let t = ok.channel.event_trigger.as_ref().unwrap();
    assert_eq!((t.nodes(), t.bucket(), t.costs()), (1, (3, 2, 6), &[1][..]));
    // λχ = 0.1·5 ≤ 1: refused by default (above), accepted on opt-in with one warning.
    let spec = parse(
        &format!("{LINEAR}{}", trigger(1, "[0.0]", 0.1, true)),
        ORIGIN,
        "x",
    )
    .unwrap();
    let w = spec.warnings();
    assert_eq!(w.len(), 1, "{w:?}");
    assert!(w[0].contains("lambda*chi") && !w[0].contains('\n'), "{w:?}");
    let e = parse(
        &format!("{LINEAR}{}", trigger(1, "[0.0]", 0.1, false)),
        ORIGIN,
        "x",
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("lambda"), "{e}");
}

#[test]
fn each_kind_of_bad_field_is_named_on_one_line() {
    // The bases are accepted: each case's error comes from its edit.
    for base in [LINEAR.to_owned(), OCCLUSION.to_owned(), two_sensors()] {
        parse(&base, ORIGIN, "base").unwrap_or_else(|e| panic!("{e}"));
    }
    let mut faults = Vec::new();
    for (what, text, names) in cases() {
        match catch_unwind(AssertUnwindSafe(|| parse(&text, ORIGIN, "case"))) {
            Err(p) => {
                let msg = p
                    .downcast_ref::<String>()
                    .cloned()
                    .or_else(|| p.downcast_ref::<&str>().map(|s| s.to_string()))
                    .unwrap_or_default();
                faults.push(format!("{what}: PANIC {msg}"));
            }
            Ok(Ok(_)) => faults.push(format!("{what}: accepted")),
            Ok(Err(e)) => {
                if let Some(f) = fault(&e, names) {
                    faults.push(format!("{what}: {f}"));
                }
            }
        }
    }
    assert!(
        faults.is_empty(),
        "{} faults:\n{}",
        faults.len(),
        faults.join("\n")
    );
}

#[test]
fn bad_files_are_refused_naming_the_path() {
    let dir = scratch();
    let one_line_naming = |e: &SpecError, path: &Path, needle: &str| {
        let s = e.to_string();
        assert!(!s.contains('\n'), "{s:?}");
        assert!(s.starts_with(&path.display().to_string()), "{s}");
        assert!(s.contains(needle), "{needle:?} not in {s}");
    };

    // Missing.
    let missing = dir.join("missing.toml");
    one_line_naming(&load(&missing).unwrap_err(), &missing, "missing.toml");
    // A directory.
    one_line_naming(&load(&dir).unwrap_err(), &dir, "");

    // Through `load`, a field error names the path too.
    let bad = dir.join("bad-gate.toml");
    std::fs::write(&bad, format!("gate = 2.0\n{LINEAR}")).unwrap();
    one_line_naming(&load(&bad).unwrap_err(), &bad, "invalid `gate`");

    // Larger than 1 MiB, though valid TOML (a comment pads it): refused by size.
    let big = dir.join("big.toml");
    let pad = MAX_FILE_BYTES as usize + 1 - LINEAR.len() - 2;
    std::fs::write(&big, format!("{LINEAR}#{}\n", "x".repeat(pad))).unwrap();
    assert_eq!(std::fs::metadata(&big).unwrap().len(), MAX_FILE_BYTES + 1);
    one_line_naming(&load(&big).unwrap_err(), &big, "larger than 1024 KiB");
    // Exactly the bound is read (and parses).
    let edge = dir.join("edge.toml");
    std::fs::write(&edge, format!("{LINEAR}#{}\n", "x".repeat(pad - 1))).unwrap();
    assert_eq!(std::fs::metadata(&edge).unwrap().len(), MAX_FILE_BYTES);
    assert_eq!(load(&edge).unwrap().name, "linear");

    // Not UTF-8: the first bad byte's offset is named.
    let latin1 = dir.join("latin1.toml");
    let mut bytes = b"name = \"caf".to_vec();
    let at = bytes.len();
    bytes.extend_from_slice(b"\xe9\"\n");
    bytes.extend_from_slice(LINEAR.replacen("name = \"linear\"", "", 1).as_bytes());
    std::fs::write(&latin1, &bytes).unwrap();
    one_line_naming(
        &load(&latin1).unwrap_err(),
        &latin1,
        &format!("not UTF-8 text (byte {at})"),
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
#[cfg(unix)]
fn an_endless_file_is_refused_quickly() {
    let zero = Path::new("/dev/zero");
    let t = Instant::now();
    let e = load(zero).unwrap_err();
    assert!(t.elapsed() < Duration::from_secs(5), "{:?}", t.elapsed());
    let s = e.to_string();
    assert!(
        s.starts_with("/dev/zero: ") && s.contains("larger than") && !s.contains('\n'),
        "{s}"
    );
}

/// A FIFO given as a spec file (`--estimator-spec /tmp/fifo`) is refused at once, naming the
/// file: opening one would wait for a writer that never comes.
#[test]
#[cfg(unix)]
fn a_fifo_is_refused_without_waiting_for_a_writer() {
    let dir = std::env::temp_dir().join(format!("estpipe-spec-fifo-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let fifo = dir.join("spec.toml");
    let made = std::process::Command::new("mkfifo").arg(&fifo).status();
    if !made.is_ok_and(|s| s.success()) {
        skip_log::skipped(
            "a_fifo_is_refused_without_waiting_for_a_writer",
            "no mkfifo to make a FIFO with",
        );
        return;
    }
    // On a thread, so that a regression hangs the thread, not the test.
    let (tx, rx) = std::sync::mpsc::channel();
    let path = fifo.clone();
    std::thread::spawn(move || {
        let _ = tx.send(load(&path).map(|_| ()).map_err(|e| e.to_string()));
    });
    let got = rx
        .recv_timeout(Duration::from_secs(5))
        .expect("load of a FIFO still waiting after 5 s");
    let e = got.unwrap_err();
    assert!(
        e.starts_with(&fifo.display().to_string()) && e.contains("FIFO") && !e.contains('\n'),
        "{e}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn deeply_nested_or_huge_text_does_not_crash() {
    // Within the size bound, text a parser could recurse on or loop over.
    let n = 200_000;
    for text in [
        format!("a = {}", "[".repeat(n)),
        format!("a = {}1{}", "[".repeat(n / 2), "]".repeat(n / 2)),
        format!("x = {}", "{ y = ".repeat(n / 8)),
        "[[sensors]]\n".repeat(n / 12),
        format!("{LINEAR}\n{}", "# comment\n".repeat(n / 10)),
    ] {
        let t = Instant::now();
        let r = catch_unwind(AssertUnwindSafe(|| parse(&text, ORIGIN, "x")));
        assert!(t.elapsed() < Duration::from_secs(10), "{:?}", t.elapsed());
        match r {
            Ok(Ok(_)) if text.starts_with(LINEAR) => {}
            Ok(Err(e)) if !text.starts_with(LINEAR) => {
                assert!(fault(&e, Names::Parser("")).is_none(), "{e}")
            }
            Ok(other) => panic!("unexpected: {:?}", other.map(|s| s.name)),
            Err(_) => panic!("parse panicked on {}…", &text[..40.min(text.len())]),
        }
    }
}
