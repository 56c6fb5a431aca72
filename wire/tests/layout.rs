//! The layouts of `estpipe_wire::layout` (the compiler's `offset_of!`/`size_of`/`align_of`)
//! against everything that restates them: the tables of `docs/wire.md`, the C header
//! (compiled and run with the system `cc`) and the Python ctypes structures. None of them can
//! drift from the Rust types without this test failing.

use estpipe_wire::layout::{layouts, TypeLayout};
use std::path::{Path, PathBuf};
use std::process::Command;

#[path = "../../tests/skip_log.rs"]
mod skip_log;

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// One table row or heading as `(type, field or "", a, b)`: a field's offset and size, a
/// type's size and alignment.
type Row = (String, String, usize, usize);

fn rust_rows(with_align: bool) -> Vec<Row> {
    let mut out = Vec::new();
    for TypeLayout {
        name,
        size,
        align,
        fields,
        ..
    } in layouts()
    {
        out.push((name.to_string(), String::new(), size, align));
        for f in fields {
            out.push((name.to_string(), f.name.to_string(), f.offset, f.size));
            if with_align {
                out.push((name.to_string(), format!("{}/align", f.name), f.align, 0));
            }
        }
    }
    out
}

/// The payload tables of docs/wire.md: `### Slot: `estpipe::wire::Slot`, size 96, align 8`
/// headings and `| offset | size | align | `field` | `type` | … |` rows.
fn doc_rows(md: &str) -> (Vec<Row>, Vec<(String, String)>) {
    let mut rows = Vec::new();
    let mut type_names = Vec::new();
    let mut current: Option<String> = None;
    let num = |s: &str| s.trim().parse::<usize>().ok();
    for line in md.lines() {
        if line.starts_with('#') {
            current = None;
        }
        if let Some(h) = line.strip_prefix("### ") {
            let Some((name, rest)) = h.split_once(':') else {
                continue;
            };
            let parts: Vec<&str> = rest.split(',').map(str::trim).collect();
            if parts.len() != 3 {
                continue;
            }
            let tn = parts[0].trim_matches('`').to_string();
            let size = parts[1].strip_prefix("size ").and_then(num);
            let align = parts[2].strip_prefix("align ").and_then(num);
            if let (Some(size), Some(align)) = (size, align) {
                current = Some(name.to_string());
                type_names.push((name.to_string(), tn));
                rows.push((name.to_string(), String::new(), size, align));
            }
            continue;
        }
        let Some(t) = &current else { continue };
        let cells: Vec<&str> = line.split('|').map(str::trim).collect();
        // "", offset, size, align, field, type, meaning, ""
        if cells.len() < 7 {
            continue;
        }
        let (Some(off), Some(size), Some(align)) = (num(cells[1]), num(cells[2]), num(cells[3]))
        else {
            continue;
        };
        let field = cells[4].trim_matches('`').to_string();
        let ty = cells[5].trim_matches('`');
        assert_eq!(
            estpipe_wire::layout::size_align_of(ty),
            Some((size, align)),
            "docs/wire.md: {t}.{field} is `{ty}` but the row says size {size}, align {align}"
        );
        rows.push((t.clone(), field.clone(), off, size));
        rows.push((t.clone(), format!("{field}/align"), align, 0));
    }
    (rows, type_names)
}

#[test]
fn docs_wire_md_tables_match_the_rust_layouts() {
    let md = std::fs::read_to_string(repo().join("docs/wire.md")).unwrap();
    let (rows, type_names) = doc_rows(&md);
    assert_eq!(rows, rust_rows(true), "docs/wire.md payload tables");
    let rust_names: Vec<(String, String)> = layouts()
        .iter()
        .map(|t| (t.name.to_string(), t.type_name.to_string()))
        .collect();
    assert_eq!(type_names, rust_names, "docs/wire.md iceoryx2 type names");
    // The version the document states.
    let v = format!("**`WIRE_VERSION` = {}**", estpipe_wire::WIRE_VERSION);
    assert!(md.contains(&v), "docs/wire.md does not say {v}");
}

#[test]
fn the_c_header_has_the_rust_layouts_at_compile_and_run_time() {
    if Command::new("cc").arg("--version").output().is_err() {
        skip_log::skipped(
            "the_c_header_has_the_rust_layouts_at_compile_and_run_time",
            "no `cc` on PATH to compile clients/c/check_layout.c",
        );
        return;
    }
    let dir = repo().join("clients/c");
    let exe = std::env::temp_dir().join(format!("estpipe-check-layout-{}", std::process::id()));
    let out = Command::new("cc")
        .args(["-std=c11", "-Wall", "-Wextra", "-Werror", "-o"])
        .arg(&exe)
        .arg(dir.join("check_layout.c"))
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "cc failed (a _Static_assert?):\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let run = Command::new(&exe).output().unwrap();
    let _ = std::fs::remove_file(&exe);
    assert!(
        run.status.success(),
        "check_layout: {}",
        String::from_utf8_lossy(&run.stderr)
    );
    // "Slot size 96 align 8" / "Slot.version offset 0 size 4"
    let rows: Vec<Row> = String::from_utf8(run.stdout)
        .unwrap()
        .lines()
        .map(|l| {
            let w: Vec<&str> = l.split_whitespace().collect();
            let (t, f) = w[0].split_once('.').unwrap_or((w[0], ""));
            (
                t.to_string(),
                f.to_string(),
                w[2].parse().unwrap(),
                w[4].parse().unwrap(),
            )
        })
        .collect();
    assert_eq!(rows, rust_rows(false), "clients/c/estpipe_wire.h");
    let header = std::fs::read_to_string(dir.join("estpipe_wire.h")).unwrap();
    let v = format!(
        "#define ESTPIPE_WIRE_VERSION {}u",
        estpipe_wire::WIRE_VERSION
    );
    assert!(header.contains(&v), "estpipe_wire.h lacks {v}");
    for t in layouts() {
        let d = format!(
            "#define ESTPIPE_TYPE_NAME_{} \"{}\"",
            t.name.to_uppercase(),
            t.type_name
        );
        assert!(header.contains(&d), "estpipe_wire.h lacks {d}");
    }
}

#[test]
fn the_python_structures_have_the_rust_layouts() {
    let python = std::env::var("ESTPIPE_PYTHON").unwrap_or_else(|_| "python3".into());
    let probe = Command::new(&python)
        .args(["-c", "import iceoryx2"])
        .output();
    if !probe.is_ok_and(|o| o.status.success()) {
        assert!(
            std::env::var_os("ESTPIPE_PYTHON").is_none(),
            "ESTPIPE_PYTHON={python} cannot import iceoryx2"
        );
        skip_log::skipped(
            "the_python_structures_have_the_rust_layouts",
            &format!(
                "`{python} -c \"import iceoryx2\"` fails (pip install -r \
                 clients/python/requirements.txt, or set ESTPIPE_PYTHON)"
            ),
        );
        return;
    }
    let out = Command::new(&python)
        .args([
            "-c",
            "import estpipe, json; print(json.dumps(estpipe.layouts()))",
        ])
        .env("PYTHONPATH", repo().join("clients/python"))
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let py: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    for t in layouts() {
        let p = &py[t.name];
        assert_eq!(p["type_name"], t.type_name, "{}", t.name);
        assert_eq!(p["size"], t.size, "{}", t.name);
        assert_eq!(p["align"], t.align, "{}", t.name);
        let fields = p["fields"].as_object().unwrap();
        assert_eq!(fields.len(), t.fields.len(), "{} field count", t.name);
        for f in &t.fields {
            assert_eq!(
                fields[f.name],
                serde_json::json!([f.offset, f.size]),
                "{}.{}",
                t.name,
                f.name
            );
        }
    }
    // The constants the Python module restates.
    let consts = Command::new(&python)
        .args([
            "-c",
            "import estpipe as e; print(e.WIRE_VERSION, e.MAX_NX, e.MAX_NY, e.MAX_NODES, e.COV_LEN, e.READY_EVENT, e.MAX_SUBSCRIBER_BUFFER, e.ESTIMATE_HISTORY)",
        ])
        .env("PYTHONPATH", repo().join("clients/python"))
        .output()
        .unwrap();
    let want = format!(
        "{} {} {} {} {} {} {} {}",
        estpipe_wire::WIRE_VERSION,
        estpipe_wire::MAX_NX,
        estpipe_wire::MAX_NY,
        estpipe_wire::MAX_NODES,
        estpipe_wire::COV_LEN,
        estpipe_wire::READY_EVENT.as_value(),
        estpipe_wire::MAX_SUBSCRIBER_BUFFER,
        estpipe_wire::ESTIMATE_HISTORY
    );
    assert_eq!(String::from_utf8_lossy(&consts.stdout).trim(), want);
}

/// The flags by name, as the docs quote them.
fn flags() -> Vec<(&'static str, u32)> {
    use estpipe_wire::*;
    vec![
        ("FLAG_TRIGGERED", FLAG_TRIGGERED),
        ("FLAG_TOKEN_BLOCKED", FLAG_TOKEN_BLOCKED),
        ("FLAG_CENSORED", FLAG_CENSORED),
        ("FLAG_RANDOM_LOSS", FLAG_RANDOM_LOSS),
        ("FLAG_OCCLUDED", FLAG_OCCLUDED),
        ("FLAG_TOKENS", FLAG_TOKENS),
        ("FLAG_NET_LOST", FLAG_NET_LOST),
        ("FLAG_IPC_LOST", FLAG_IPC_LOST),
    ]
}

/// A value as the docs write it: decimal, or a power of two `2³⁰`.
fn doc_value(s: &str) -> Option<u64> {
    let s = s.trim();
    if let Some(exp) = s.strip_prefix('2') {
        if !exp.is_empty() && exp.chars().all(|c| "⁰¹²³⁴⁵⁶⁷⁸⁹".contains(c)) {
            let digits: String = exp
                .chars()
                .map(|c| {
                    char::from(b'0' + "⁰¹²³⁴⁵⁶⁷⁸⁹".chars().position(|d| d == c).unwrap() as u8)
                })
                .collect();
            return Some(1u64 << digits.parse::<u32>().ok()?);
        }
    }
    s.parse().ok()
}

/// Every docs/*.md page and the README, with its name.
fn pages() -> Vec<(String, String)> {
    let mut pages = vec![("README.md".to_string(), repo().join("README.md"))];
    for e in std::fs::read_dir(repo().join("docs")).unwrap() {
        let p = e.unwrap().path();
        if p.extension().is_some_and(|x| x == "md") {
            pages.push((
                format!("docs/{}", p.file_name().unwrap().to_string_lossy()),
                p,
            ));
        }
    }
    pages
        .into_iter()
        .map(|(n, p)| (n, std::fs::read_to_string(p).unwrap()))
        .collect()
}

/// What the docs quote of the wire's constants is what `estpipe_wire` says: every flag in a
/// table row (`| \`FLAG_…\` | value |`) and every flag written as `value (\`FLAG_…\``; every
/// `2³⁰ = n`; the version of every JSON header (`"wire_version":n`) and of every refusal quoted
/// from the code (`wire version n requires`, `needs`); the array sizes.
#[test]
fn the_docs_quote_the_wires_constants() {
    let flags = flags();
    let mut checked = 0;
    for (page, md) in pages() {
        for (i, line) in md.lines().enumerate() {
            let at = format!("{page}:{}", i + 1);
            // Table rows naming one flag.
            if let Some(rest) = line.strip_prefix("| `FLAG_") {
                let name = format!("FLAG_{}", rest.split('`').next().unwrap());
                let value = rest.split('|').nth(1).and_then(doc_value);
                let want = flags.iter().find(|f| f.0 == name);
                assert!(want.is_some(), "{at}: {name} is no flag of estpipe_wire");
                assert_eq!(value, Some(u64::from(want.unwrap().1)), "{at}: {name}");
                checked += 1;
            }
            // `value (`FLAG_…`` inline.
            for (name, v) in &flags {
                let tag = format!(" (`{name}`");
                let mut from = 0;
                while let Some(pos) = line[from..].find(&tag) {
                    let before = &line[..from + pos];
                    let mut words = before.rsplit([' ', '(']);
                    let word = words.next().unwrap_or("");
                    // `bit 31 (`FLAG_IPC_LOST`` names the bit, not the value.
                    let bit = words.next() == Some("bit");
                    let value = doc_value(word).map(|n| if bit { 1 << n } else { n });
                    if let Some(n) = value {
                        assert_eq!(n, u64::from(*v), "{at}: {name} quoted as {word}");
                        checked += 1;
                    }
                    from += pos + tag.len();
                }
            }
            // `2³⁰ = 1073741824`.
            for (pow, n) in [("2³⁰ = ", 1u64 << 30), ("2³¹ = ", 1u64 << 31)] {
                if let Some(pos) = line.find(pow) {
                    let digits: String = line[pos + pow.len()..]
                        .chars()
                        .take_while(char::is_ascii_digit)
                        .collect();
                    assert_eq!(digits.parse::<u64>().ok(), Some(n), "{at}: {pow}");
                    checked += 1;
                }
            }
            // The version of a header's JSON and of a refusal quoted from the code.
            for tag in ["\"wire_version\":", "wire version "] {
                let mut from = 0;
                while let Some(pos) = line[from..].find(tag) {
                    let after = &line[from + pos + tag.len()..];
                    let digits: String = after.chars().take_while(char::is_ascii_digit).collect();
                    let quoted = tag.starts_with('"')
                        || after[digits.len()..].starts_with(" requires")
                        || after[digits.len()..].starts_with(" needs");
                    if quoted {
                        assert_eq!(
                            digits.parse::<u32>().ok(),
                            Some(estpipe_wire::WIRE_VERSION),
                            "{at}: {tag}{digits}"
                        );
                        checked += 1;
                    }
                    from += pos + tag.len();
                }
            }
        }
    }
    let md = std::fs::read_to_string(repo().join("docs/wire.md")).unwrap();
    let sizes = format!(
        "| `MAX_NX`, `MAX_NY`, `MAX_NODES` | {}, {}, {} |",
        estpipe_wire::MAX_NX,
        estpipe_wire::MAX_NY,
        estpipe_wire::MAX_NODES
    );
    assert!(md.contains(&sizes), "docs/wire.md does not say {sizes}");
    let cov = format!("| `COV_LEN` | {} |", estpipe_wire::COV_LEN);
    assert!(md.contains(&cov), "docs/wire.md does not say {cov}");
    // The constants table alone has eight flags; the rest are quotes elsewhere.
    assert!(
        checked >= 12,
        "only {checked} quotes found: the patterns no longer match the docs"
    );
}
