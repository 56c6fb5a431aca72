//! `parse` on arbitrary input: an error of one line naming the origin, or a spec; never a
//! panic. Inputs: random bytes (as lossy UTF-8), the example files with random edits, and
//! TOML assembled from the spec's own keys with random values.

use estpipe_spec::file::parse;
use proptest::prelude::*;

const LINEAR: &str = include_str!("../../specs/linear.toml");
const OCCLUSION: &str = include_str!("../../specs/occlusion.toml");
const ORIGIN: &str = "prop.toml";

fn check(text: &str) {
    match parse(text, ORIGIN, "prop") {
        Ok(spec) => {
            // Whatever is accepted is usable: the fingerprint and the header can be formed.
            let _ = spec.stream_header();
            assert!(spec.nx() >= 1 && spec.nodes() >= 1);
        }
        Err(e) => {
            let s = e.to_string();
            assert!(s.starts_with(ORIGIN), "{s}");
            assert!(!s.contains('\n'), "{s:?}");
        }
    }
}

/// Numbers a hostile file might hold.
fn number() -> impl Strategy<Value = String> {
    prop_oneof![
        any::<f64>().prop_map(|v| format!("{v:?}")),
        (-3i64..4).prop_map(|v| format!("{v}.0")),
        Just("nan".to_owned()),
        Just("-inf".to_owned()),
        Just("1e308".to_owned()),
        Just("-0.0".to_owned()),
        Just("5e-324".to_owned()),
        any::<i64>().prop_map(|v| v.to_string()),
        Just("\"x\"".to_owned()),
    ]
}

fn vector() -> impl Strategy<Value = String> {
    prop::collection::vec(number(), 0..5).prop_map(|v| format!("[{}]", v.join(", ")))
}

fn matrix() -> impl Strategy<Value = String> {
    prop::collection::vec(vector(), 0..5).prop_map(|v| format!("[{}]", v.join(", ")))
}

/// A file of the spec's shape: every table, each value random.
fn spec_like() -> impl Strategy<Value = String> {
    (
        (matrix(), prop::option::of(matrix()), matrix()),
        (vector(), matrix()),
        prop::collection::vec((matrix(), prop::option::of(matrix()), matrix()), 0..3),
        prop::option::of((vector(), number(), vector(), vector())),
        prop::option::of(prop::collection::vec(vector(), 0..3)),
        prop::option::of((0u32..8, 0u32..8, 0u32..8, 0u32..8)),
        prop::option::of((
            0u32..8,
            prop::collection::vec((number(), number(), number(), vector()), 0..3),
        )),
        (prop::option::of(number()), prop::option::of(number())),
    )
        .prop_map(
            |((a, b, q), (mean, cov), sensors, occ, tobit, bucket, trig, (loss, gate))| {
                let mut s = String::new();
                if let Some(l) = loss {
                    s += &format!("loss_rate = {l}\n");
                }
                if let Some(g) = gate {
                    s += &format!("gate = {g}\n");
                }
                s += &format!("[model]\na = {a}\nq = {q}\n");
                if let Some(b) = b {
                    s += &format!("b = {b}\n");
                }
                s += &format!("[prior]\nmean = {mean}\ncov = {cov}\n");
                for (c, d, r) in sensors {
                    s += &format!("[[sensors]]\nc = {c}\nr = {r}\n");
                    if let Some(d) = d {
                        s += &format!("d = {d}\n");
                    }
                }
                if let Some((e, psi, centres, radii)) = occ {
                    s += &format!(
                        "[occlusion]\ne = {e}\npsi = {psi}\ncentres = {centres}\nradii = {radii}\n"
                    );
                }
                if let Some(t) = tobit {
                    s += &format!("[tobit]\nthresholds = [{}]\n", t.join(", "));
                }
                if let Some((a, b, sz, z0)) = bucket {
                    s += &format!("[token_bucket]\na = {a}\nb = {b}\ns = {sz}\nz0 = {z0}\n");
                }
                if let Some((capacity, nodes)) = trig {
                    s += &format!(
                        "[event_trigger]\ninitial_tokens = 1\nrate = 1\ncapacity = {capacity}\n"
                    );
                    for (sigma, chi, lambda, reference) in nodes {
                        s += &format!(
                        "[[event_trigger.nodes]]\nsigma = {sigma}\nchi = {chi}\nlambda = {lambda}\n\
                         eta0 = 1.0\nreference = {reference}\ncost = 1\n"
                    );
                    }
                }
                s
            },
        )
}

/// A `rows × cols` matrix of benign numbers (identity-like, so shapes are the only problem).
fn shaped(rows: usize, cols: usize) -> String {
    let r: Vec<String> = (0..rows)
        .map(|i| {
            let e: Vec<&str> = (0..cols)
                .map(|j| if i == j { "1.0" } else { "0.0" })
                .collect();
            format!("[{}]", e.join(", "))
        })
        .collect();
    format!("[{}]", r.join(", "))
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 512, ..ProptestConfig::default() })]

    #[test]
    fn random_bytes_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..512)) {
        check(&String::from_utf8_lossy(&bytes));
    }

    #[test]
    fn random_text_never_panics(text in "[\\[\\]{}=.,\"a-z0-9_\\- \n#]{0,300}") {
        check(&text);
    }

    #[test]
    fn edited_examples_never_panic(
        which in any::<bool>(),
        at in any::<prop::sample::Index>(),
        len in 0usize..40,
        insert in "[\\[\\]{}=.,\"a-z0-9_\\-+e \n]{0,20}",
    ) {
        let base = if which { LINEAR } else { OCCLUSION };
        let start = at.index(base.len() + 1);
        let end = (start + len).min(base.len());
        if base.is_char_boundary(start) && base.is_char_boundary(end) {
            check(&format!("{}{insert}{}", &base[..start], &base[end..]));
        }
    }

    #[test]
    fn spec_shaped_files_never_panic(text in spec_like()) {
        check(&text);
    }

    /// Well-formed shapes with random entries: a valid linear spec with numbers replaced.
    #[test]
    fn example_with_random_numbers_never_panics(
        v in prop::collection::vec(number(), 16),
    ) {
        let text = format!(
            "[model]\na = [[{}, {}], [{}, {}]]\nb = [[{}, {}], [{}, {}]]\nq = [[{}, 0.0], [0.0, {}]]\n\
             [prior]\nmean = [{}, {}]\ncov = [[{}, 0.0], [0.0, 1.0]]\n\
             [[sensors]]\nc = [[{}, 0.0]]\nd = [[{}]]\nr = [[{}]]\n",
            v[0], v[1], v[2], v[3], v[4], v[5], v[6], v[7], v[8], v[9], v[10], v[11], v[12],
            v[13], v[14], v[15]
        );
        check(&text);
    }

    /// Every matrix and vector of some random shape (mostly the right one, 2), entries benign: the shape checks come
    /// before anything multiplies (a 3×3 prior.cov for n_x = 2 once panicked in the overflow
    /// check).
    #[test]
    fn random_shapes_never_panic(
        d in prop::collection::vec(prop_oneof![3 => Just(2usize), 1 => 0usize..5], 15),
    ) {
        let mean = format!("[{}]", vec!["0.0"; d[14]].join(", "));
        let text = format!(
            "[model]\na = {}\nb = {}\nq = {}\n[prior]\nmean = {mean}\ncov = {}\n\
             [[sensors]]\nc = {}\nd = {}\nr = {}\n",
            shaped(d[0], d[1]), shaped(d[2], d[3]), shaped(d[4], d[5]), shaped(d[6], d[7]),
            shaped(d[8], d[9]), shaped(d[10], d[11]), shaped(d[12], d[13]),
        );
        check(&text);
    }
}
