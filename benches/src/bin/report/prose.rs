//! The report's prose lives in `prose/*.md`, one file per passage, so that it is edited as
//! markdown rather than as Rust string literals. A file holds exactly the text that lands in
//! `BENCHMARKS.md` (one line per paragraph, as the generated file has it), ending with one
//! newline; values known only at run time are `{name}` placeholders.

use std::fmt::Display;

/// The passage `template` with each `{name}` of `vars` replaced by its value.
///
/// # Panics
///
/// If a name of `vars` is not in the template, or a placeholder is left unfilled: the code and
/// the markdown disagree, which each part's test catches before a run does.
pub fn fill(template: &str, vars: &[(&str, &dyn Display)]) -> String {
    let mut text = template.to_string();
    for (name, value) in vars {
        let key = format!("{{{name}}}");
        assert!(text.contains(&key), "prose without {key}: {template:.60}…");
        text = text.replace(&key, &value.to_string());
    }
    if let Some(at) = placeholder(&text) {
        panic!("prose with an unfilled {}", &text[at..]);
    }
    text
}

/// Appends a passage and the blank line that ends it.
pub fn push(md: &mut String, passage: &str) {
    md.push_str(passage);
    md.push('\n');
}

/// Where the first `{name}` of `text` starts, if any.
fn placeholder(text: &str) -> Option<usize> {
    text.match_indices('{').map(|(at, _)| at).find(|&at| {
        let rest = &text[at + 1..];
        let name = rest.len() - rest.trim_start_matches(is_name_char).len();
        name > 0 && rest[name..].starts_with('}')
    })
}

fn is_name_char(c: char) -> bool {
    c.is_ascii_alphanumeric() || c == '_'
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fills_every_occurrence_with_the_display_of_its_value() {
        let t = "{n} times back to back and {n} times at {rate} Hz.\n";
        assert_eq!(
            fill(t, &[("n", &30_000), ("rate", &10_000.0)]),
            "30000 times back to back and 30000 times at 10000 Hz.\n"
        );
    }

    #[test]
    fn braces_that_are_not_placeholders_stay() {
        assert_eq!(fill("{ a } {} {x", &[]), "{ a } {} {x");
    }

    #[test]
    #[should_panic(expected = "unfilled {rounds}")]
    fn an_unfilled_placeholder_panics() {
        fill("`--rounds {rounds}`", &[]);
    }

    #[test]
    #[should_panic(expected = "prose without {n}")]
    fn a_value_without_its_placeholder_panics() {
        fill("no placeholder", &[("n", &1)]);
    }
}
