//! Code health: no function in `src/` is longer than [`MAX_FN_LINES`] lines (from its `fn`
//! line to its closing brace), so that each one can be read as one thing. The scanner
//! matches braces on the source with comments, string literals (plain, byte, raw) and
//! character literals blanked out, so a `"}"` or a `// {` cannot shift a function's end.

use std::path::{Path, PathBuf};

const MAX_FN_LINES: usize = 150;

/// `src` with comments, string and character literals replaced by spaces (newlines kept,
/// so line numbers still hold).
fn blank_literals(src: &str) -> String {
    let c: Vec<char> = src.chars().collect();
    let mut out: Vec<char> = c.clone();
    let blank = |out: &mut Vec<char>, from: usize, to: usize| {
        for ch in &mut out[from..to.min(c.len())] {
            if *ch != '\n' {
                *ch = ' ';
            }
        }
    };
    let ident = |ch: char| ch.is_alphanumeric() || ch == '_';
    let mut i = 0;
    while i < c.len() {
        let at = |k: usize| c.get(k).copied().unwrap_or('\0');
        let start = i;
        if at(i) == '/' && at(i + 1) == '/' {
            while i < c.len() && c[i] != '\n' {
                i += 1;
            }
        } else if at(i) == '/' && at(i + 1) == '*' {
            // Block comments nest in Rust.
            let mut depth = 0;
            loop {
                if i >= c.len() {
                    break;
                } else if at(i) == '/' && at(i + 1) == '*' {
                    depth += 1;
                    i += 2;
                } else if at(i) == '*' && at(i + 1) == '/' {
                    depth -= 1;
                    i += 2;
                    if depth == 0 {
                        break;
                    }
                } else {
                    i += 1;
                }
            }
        } else if (at(i) == 'r' || (at(i) == 'b' && at(i + 1) == 'r'))
            && (i == 0 || !ident(c[i - 1]))
            && {
                let mut k = i + if at(i) == 'b' { 2 } else { 1 };
                while at(k) == '#' {
                    k += 1;
                }
                at(k) == '"'
            }
        {
            // Raw string r#"…"#: ends at a quote followed by as many hashes.
            let mut k = i + if at(i) == 'b' { 2 } else { 1 };
            let mut hashes = 0;
            while at(k) == '#' {
                hashes += 1;
                k += 1;
            }
            i = k + 1;
            while i < c.len() && !(c[i] == '"' && (1..=hashes).all(|h| at(i + h) == '#')) {
                i += 1;
            }
            i += 1 + hashes;
        } else if at(i) == '"' {
            i += 1;
            while i < c.len() && c[i] != '"' {
                i += if c[i] == '\\' { 2 } else { 1 };
            }
            i += 1;
        } else if at(i) == '\'' {
            // A character literal ('x', '\n', '\u{7d}'), else a lifetime or label ('a).
            if at(i + 1) == '\\' {
                // Past the quote, the backslash and the escaped character (maybe a quote).
                i += 3;
                while i < c.len() && c[i] != '\'' {
                    i += 1;
                }
                i += 1;
            } else if at(i + 2) == '\'' {
                i += 3;
            } else {
                i += 1;
                continue;
            }
        } else {
            i += 1;
            continue;
        }
        blank(&mut out, start, i);
    }
    out.into_iter().collect()
}

/// Every function with a body in `src`: (name, first line, number of lines), lines from 1.
fn functions(src: &str) -> Vec<(String, usize, usize)> {
    let s: Vec<char> = blank_literals(src).chars().collect();
    let line_at = |k: usize| 1 + s[..k].iter().filter(|&&ch| ch == '\n').count();
    let ident = |ch: char| ch.is_alphanumeric() || ch == '_';
    let mut out = Vec::new();
    let mut i = 0;
    while i + 2 < s.len() {
        let is_fn = s[i] == 'f'
            && s[i + 1] == 'n'
            && s[i + 2].is_whitespace()
            && (i == 0 || !ident(s[i - 1]));
        if !is_fn {
            i += 1;
            continue;
        }
        let mut k = i + 2;
        while k < s.len() && s[k].is_whitespace() {
            k += 1;
        }
        let name: String = s[k..].iter().take_while(|&&ch| ident(ch)).collect();
        // The body starts at the first `{` outside brackets, unless a `;` outside brackets
        // (not the one of an array type `[f32; 8]`) ends a declaration without a body first.
        let mut open = k;
        let mut nest = 0i32;
        while open < s.len() {
            match s[open] {
                '(' | '[' => nest += 1,
                ')' | ']' => nest -= 1,
                '{' | ';' if nest == 0 => break,
                _ => {}
            }
            open += 1;
        }
        if name.is_empty() || open >= s.len() || s[open] == ';' {
            i = k;
            continue;
        }
        let mut depth = 0usize;
        let mut close = open;
        while close < s.len() {
            match s[close] {
                '{' => depth += 1,
                '}' => {
                    depth -= 1;
                    if depth == 0 {
                        break;
                    }
                }
                _ => {}
            }
            close += 1;
        }
        assert!(close < s.len(), "unbalanced braces in fn {name}");
        let first = line_at(i);
        out.push((name, first, line_at(close) - first + 1));
        // Continue inside the body: nested functions are measured too.
        i = open;
    }
    out
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let p = entry.unwrap().path();
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|e| e == "rs") {
            out.push(p);
        }
    }
}

#[test]
fn no_function_in_src_is_longer_than_the_limit() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let mut files = Vec::new();
    rust_files(&root.join("src"), &mut files);
    files.sort();
    let mut too_long = Vec::new();
    let mut count = 0;
    for f in &files {
        let rel = f
            .strip_prefix(&root)
            .unwrap()
            .to_string_lossy()
            .replace('\\', "/");
        let src = std::fs::read_to_string(f).unwrap();
        for (name, line, len) in functions(&src) {
            count += 1;
            if len <= MAX_FN_LINES {
                continue;
            }
            too_long.push(format!("{rel}:{line} fn {name}: {len} lines"));
        }
    }
    // The scan saw the crate (a broken scanner finding nothing would pass otherwise).
    assert!(count > 1000, "only {count} functions found in src/");
    assert!(
        too_long.is_empty(),
        "functions over {MAX_FN_LINES} lines (split them by meaning):\n{}",
        too_long.join("\n")
    );
}

/// Braces inside comments, strings, raw strings and character literals do not count, and
/// lifetimes are not character literals.
#[test]
fn scanner_ignores_braces_in_literals_and_comments() {
    let src = r####"
fn a<'x>(s: &'x str) -> char {
    let _ = "}}\"}";
    let _ = r#"}"#;
    let _ = br##"}"# }"##;
    let _ = b"}";
    // }
    /* } /* nested } */ } */
    let _ = '}';
    let _ = '\'';
    let _ = ['\'','{'];
    let _ = '\u{7d}';
    '{'
}
trait T {
    fn declared(&self);
}
fn b(x: [u8; 2]) -> [u8; 2] {
    fn inner() {}
    x
}
"####;
    let f = functions(src);
    let names: Vec<(&str, usize, usize)> = f.iter().map(|(n, a, l)| (n.as_str(), *a, *l)).collect();
    assert_eq!(names, [("a", 2, 13), ("b", 18, 4), ("inner", 19, 1)]);
}

/// A function over the limit is found (the main test can fail).
#[test]
fn scanner_measures_a_long_function() {
    let body: String = (0..MAX_FN_LINES)
        .map(|i| format!("    let x{i} = {i};\n"))
        .collect();
    let src = format!("fn long() {{\n{body}}}\n");
    assert_eq!(functions(&src), [("long".to_string(), 1, MAX_FN_LINES + 2)]);
}
