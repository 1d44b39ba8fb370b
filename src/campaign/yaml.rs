//! YAML reading with errors that point at the file, line, column and key path.
//!
//! Two tools: [`parse`] turns a YAML text into a typed config (unknown keys and wrong types
//! come back as `file:line:col: key.path: message`), and [`Doc::error`] does the same for
//! problems found after parsing (a negative energy, a wavelength missing from a table), by
//! walking the document again to find where the offending key sits.

use crate::error::{Error, Result};
use serde::de::{
    self, DeserializeOwned, DeserializeSeed, IgnoredAny, MapAccess, SeqAccess, Visitor,
};
use std::fmt;
use std::path::{Path, PathBuf};

/// A YAML file read from disk, kept so that later checks can point into it.
#[derive(Clone, Debug)]
pub struct Doc {
    pub path: PathBuf,
    pub text: String,
}

impl Doc {
    pub fn read(path: &Path) -> Result<Doc> {
        let text = crate::error::read_text(path)?;
        if text.trim().is_empty() {
            return Err(Error::file(path, "the file is empty"));
        }
        Ok(Doc {
            path: path.to_path_buf(),
            text,
        })
    }

    pub fn parse<T: DeserializeOwned>(&self) -> Result<T> {
        parse(&self.path, &self.text)
    }

    /// An error at the key path `key` (dotted, `[i]` for list items), located in the text.
    pub fn error(&self, key: &str, text: impl fmt::Display) -> Error {
        Error::at(&self.path, locate(&self.text, key), key, text)
    }

    /// An error at the entry of `key` in the file's `sweep:` section, whose keys are dotted
    /// paths written as one YAML key (so [`locate`] cannot walk to them).
    pub fn sweep_error(&self, key: &str, text: impl fmt::Display) -> Error {
        let full = format!("sweep.{key}");
        let Some(sweep_at) = self.text.find("sweep:") else {
            return self.error(&full, text);
        };
        let Some(found) = self.text[sweep_at..].find(key).map(|i| sweep_at + i) else {
            return self.error(&full, text);
        };
        let line = self.text[..found].matches('\n').count() + 1;
        let col = found - self.text[..found].rfind('\n').map_or(0, |i| i + 1) + 1;
        Error::at(&self.path, Some((line, col)), &full, text)
    }

    /// Resolves a path named in this file against the file's own folder.
    pub fn resolve(&self, relative: &str) -> PathBuf {
        let p = Path::new(relative);
        if p.is_absolute() {
            p.to_path_buf()
        } else {
            self.path.parent().unwrap_or(Path::new(".")).join(p)
        }
    }
}

/// Parses `text` (read from `path`) into `T`, with a located message on failure.
pub fn parse<T: DeserializeOwned>(path: &Path, text: &str) -> Result<T> {
    too_deep(path, text)?;
    // A mapping's repeated key (two `bark:` under `materials:`) would keep the last value
    // without a word where the type is a map; serde_yaml's own Value refuses it.
    if let Err(e) = serde_yaml::from_str::<serde_yaml::Value>(text) {
        let message = e.to_string();
        if message.contains("more than one document") {
            // the separator that starts the second document (the first may open with one)
            let second = text
                .lines()
                .enumerate()
                .filter(|(_, l)| l.starts_with("---"))
                .map(|(i, _)| i + 1)
                .find(|&line| {
                    text.lines().take(line - 1).any(|l| {
                        !l.trim().is_empty() && !l.starts_with('#') && !l.starts_with("---")
                    })
                });
            return Err(Error::at(
                path,
                second.map(|l| (l, 1)),
                "",
                "a second YAML document starts here (---): the file holds one; remove the \
                 line and what follows it, or put that document in a file of its own",
            ));
        }
        if let Some(key) = message
            .split_once("duplicate entry with key \"")
            .and_then(|(_, rest)| rest.split_once('"'))
            .map(|(k, _)| k.to_string())
        {
            // serde_yaml points at the mapping; the second time the key stands is the place
            let mapping = e.location().map(|l| (l.line(), l.column()));
            let second = mapping.and_then(|(line, col)| {
                text.lines()
                    .enumerate()
                    .skip(line - 1)
                    .filter(|(_, l)| {
                        let indent = l.len() - l.trim_start().len();
                        let t = l.trim_start();
                        indent + 1 == col
                            && (t.starts_with(&format!("{key}:"))
                                || t.starts_with(&format!("\"{key}\":")))
                    })
                    .nth(1)
                    .map(|(i, _)| (i + 1, col))
            });
            return Err(Error::at(
                path,
                second.or(mapping),
                &key,
                "given twice in the same mapping: keep one",
            ));
        }
        // text that is no YAML at all (`scene: [x` unclosed): the typed reading would meet a
        // type before the end of the text, and blame the key
        let location = e.location().map(|l| (l.line(), l.column()));
        if let Some(syntax) = syntax_words(&bare_message(&message), text, location) {
            return Err(Error::at(path, location, "", syntax));
        }
    }
    let de = serde_yaml::Deserializer::from_str(text);
    match serde_path_to_error::deserialize::<_, T>(de) {
        Ok(v) => Ok(v),
        Err(e) => {
            let key = e.path().to_string();
            let key = if key == "." { String::new() } else { key };
            let inner = e.into_inner();
            let location = inner.location().map(|l| (l.line(), l.column()));
            let message = plain_words(&bare_message(&inner.to_string()));
            // the scanner's own errors are of the text, not of the key parsed before them
            if let Some(syntax) = syntax_words(&message, text, location) {
                return Err(Error::at(path, location, "", syntax));
            }
            let mut message = message;
            for nothing in ["``", "`~`", "`null`", "`Null`", "`NULL`"] {
                message = message.replace(
                    &format!("unknown variant {nothing}, expected"),
                    "found nothing, expected",
                );
            }
            // a required key left out: named as the key, said so in words
            if let Some(field) = message
                .strip_prefix("missing field `")
                .and_then(|r| r.split_once('`'))
                .map(|(f, _)| f.to_string())
            {
                let key = if key.is_empty() {
                    field
                } else {
                    format!("{key}.{field}")
                };
                return Err(Error::at(
                    path,
                    location,
                    &key,
                    "required, and missing: add it",
                ));
            }
            // serde reports an unknown key against its parent: name the key itself.
            let key = match unknown_field_name(&message) {
                Some(field) if key.is_empty() => field,
                Some(field) if !key.ends_with(&field) => format!("{key}.{field}"),
                _ => key,
            };
            Err(Error::at(path, location, &key, message))
        }
    }
}

/// Deeper flow nesting than any campaign or scene has: serde_yaml refuses past 128 levels
/// anyway, but its scanner takes time quadratic in the depth to get there (100,000 brackets
/// were 20 s of one core).
const MAX_FLOW_DEPTH: usize = 1000;

/// Refuses brackets (`[`, `{`) nested deeper than [`MAX_FLOW_DEPTH`] before the YAML parser
/// sees them, at the bracket past the limit and under the key of its line. Quoted text and
/// comments are skipped roughly (a bracket counted in a plain scalar only makes the count
/// higher, and nothing near the limit is a campaign).
fn too_deep(path: &Path, text: &str) -> Result<()> {
    let (mut depth, mut quote, mut escaped) = (0usize, None, false);
    for (line_k, line) in text.split('\n').enumerate() {
        let (mut comment, mut prev) = (false, ' ');
        for (col, c) in line.chars().enumerate() {
            match (quote, c) {
                // `\"` inside a double-quoted scalar does not close it
                (Some('"'), _) if escaped => escaped = false,
                (Some('"'), '\\') => escaped = true,
                (Some(q), _) if c == q => quote = None,
                (Some(_), _) => {}
                _ if comment => {}
                (None, '#') if prev.is_whitespace() => comment = true,
                // a quote opens a quoted scalar only where a token starts (`it's` is plain)
                (None, '"' | '\'') if prev.is_whitespace() || "[{,:".contains(prev) => {
                    quote = Some(c)
                }
                (None, '[' | '{') => {
                    depth += 1;
                    if depth > MAX_FLOW_DEPTH {
                        let key = line
                            .split_once(':')
                            .map_or("", |(k, _)| k.trim().trim_start_matches("- "));
                        return Err(Error::at(
                            path,
                            Some((line_k + 1, col + 1)),
                            key,
                            format!(
                                "brackets nested more than {MAX_FLOW_DEPTH} deep: no campaign or scene needs more than a few"
                            ),
                        ));
                    }
                }
                (None, ']' | '}') => depth = depth.saturating_sub(1),
                _ => {}
            }
            prev = c;
        }
    }
    Ok(())
}

/// serde_yaml's display adds its own path prefix and an " at line L column C" suffix: the
/// error we build carries both in a fixed form, so strip them.
fn bare_message(display: &str) -> String {
    let mut s = display.to_string();
    if let Some(i) = s.rfind(" at line ") {
        if s[i + 9..]
            .chars()
            .all(|c| c.is_ascii_digit() || c == ' ' || c.is_ascii_alphabetic())
        {
            s.truncate(i);
        }
    }
    if let Some(i) = s.find(": ") {
        let head = &s[..i];
        if !head.is_empty() && !head.contains(' ') && !head.contains('`') {
            s = s[i + 2..].to_string();
        }
    }
    s
}

/// YAML's scanner errors in a reader's words, without the place the error gives already
/// ("… at line 12 column 1, while scanning a plain scalar"); None for other messages.
fn syntax_words(message: &str, text: &str, at: Option<(usize, usize)>) -> Option<String> {
    // a tab in the indentation of the line the scanner stopped at, whatever it calls it
    let tab_indented = at
        .and_then(|(line, _)| text.lines().nth(line.saturating_sub(1)))
        .is_some_and(|l| {
            l.chars()
                .take_while(|c| c.is_whitespace() || *c == '-')
                .any(|c| c == '\t')
        });
    if message.contains("found a tab character") || (tab_indented && message.contains(" at line "))
    {
        return Some(
            "a tab character where YAML expects indentation: indent with spaces".to_string(),
        );
    }
    let (what, _) = message.split_once(" at line ")?;
    message
        .contains(", while ")
        .then(|| format!("{what} (YAML syntax)"))
}

/// serde's "invalid type: string \"high\", expected f64" in a reader's words, as the contract
/// writes it: "expected a number, found \"high\"". Other messages pass unchanged.
pub(crate) fn plain_words(message: &str) -> String {
    let Some(rest) = message
        .strip_prefix("invalid type: ")
        .or_else(|| message.strip_prefix("invalid value: "))
    else {
        return message.to_string();
    };
    let Some(i) = rest.rfind(", expected ") else {
        return message.to_string();
    };
    let (found, expected) = (&rest[..i], &rest[i + ", expected ".len()..]);
    let found = if let Some(s) = found.strip_prefix("string ") {
        s.to_string()
    } else if let Some((kind, v)) = found.split_once(" `") {
        match kind {
            // "integer `18446744073709551616` as u128": the value alone
            "integer" | "boolean" | "character" => v.split('`').next().unwrap_or(v).to_string(),
            // 1e300 as 1e300, not as its 301 digits
            "floating point" => {
                let text = v.split('`').next().unwrap_or(v);
                text.parse::<f64>().map_or_else(
                    |_| text.to_string(),
                    |x| {
                        // 7.0 where a whole number is asked for reads "found 7" otherwise
                        let shown = crate::campaign::shown(x);
                        if shown.contains(['.', 'e', 'i', 'N']) {
                            shown
                        } else {
                            format!("{shown}.0")
                        }
                    },
                )
            }
            _ => found.to_string(),
        }
    } else {
        match found {
            "sequence" => "a list".to_string(),
            "map" => "a mapping".to_string(),
            "unit value" => "nothing (null)".to_string(),
            _ => found.to_string(),
        }
    };
    let expected = match expected {
        "f64" | "f32" => "a number",
        "u8" => "a whole number from 0 to 255",
        "u16" => "a whole number from 0 to 65535",
        "u32" => "a whole number from 0 to 4294967295",
        "u64" | "u128" | "usize" => "a whole number ≥ 0",
        "i8" | "i16" | "i32" | "i64" | "i128" | "isize" => "a whole number",
        "a boolean" | "bool" => "true or false",
        "a sequence" => "a list",
        "a map" => "a mapping of keys",
        e if e.starts_with("struct ") => "a mapping of keys",
        e => e,
    };
    format!("expected {expected}, found {found}")
}

fn unknown_field_name(message: &str) -> Option<String> {
    let rest = message.strip_prefix("unknown field `")?;
    let end = rest.find('`')?;
    Some(rest[..end].to_string())
}

#[derive(Debug, Clone, PartialEq)]
enum Seg {
    Key(String),
    Index(usize),
}

fn split_path(key: &str) -> Vec<Seg> {
    let mut out = Vec::new();
    for part in key.split('.') {
        let mut rest = part;
        if let Some(i) = rest.find('[') {
            if i > 0 {
                out.push(Seg::Key(rest[..i].to_string()));
            }
            rest = &rest[i..];
            while let Some(stripped) = rest.strip_prefix('[') {
                let end = stripped.find(']').unwrap_or(stripped.len());
                if let Ok(n) = stripped[..end].parse() {
                    out.push(Seg::Index(n));
                }
                rest = stripped.get(end + 1..).unwrap_or("");
            }
        } else if !rest.is_empty() {
            out.push(Seg::Key(rest.to_string()));
        }
    }
    out
}

const FOUND: &str = "\u{1}found";

/// Line and column (1-based) of the value at `key` in a YAML text, found by walking the
/// document with serde_yaml itself, so flow style (`{ a: 1 }`) works as well as block style.
/// When the key is absent, the nearest existing parent is returned.
pub fn locate(text: &str, key: &str) -> Option<(usize, usize)> {
    let segs = split_path(key);
    for n in (0..=segs.len()).rev() {
        let de = serde_yaml::Deserializer::from_str(text);
        if let Err(e) = Seek(&segs[..n]).deserialize(de) {
            if e.to_string().starts_with(FOUND) || e.to_string().contains(FOUND) {
                return e.location().map(|l| (l.line(), l.column()));
            }
        }
    }
    None
}

struct Seek<'a>(&'a [Seg]);

impl<'de> DeserializeSeed<'de> for Seek<'_> {
    type Value = ();
    fn deserialize<D: de::Deserializer<'de>>(self, d: D) -> std::result::Result<(), D::Error> {
        d.deserialize_any(SeekVisitor(self.0))
    }
}

struct SeekVisitor<'a>(&'a [Seg]);

impl SeekVisitor<'_> {
    fn leaf<E: de::Error>(&self) -> std::result::Result<(), E> {
        if self.0.is_empty() {
            Err(E::custom(FOUND))
        } else {
            Ok(())
        }
    }
}

/// A map key of any scalar type, as text (reflectance tables use numbers as keys).
struct AnyKey(String);

impl<'de> de::Deserialize<'de> for AnyKey {
    fn deserialize<D: de::Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        struct V;
        impl Visitor<'_> for V {
            type Value = AnyKey;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("a scalar key")
            }
            fn visit_str<E>(self, v: &str) -> std::result::Result<AnyKey, E> {
                Ok(AnyKey(v.to_string()))
            }
            fn visit_i64<E>(self, v: i64) -> std::result::Result<AnyKey, E> {
                Ok(AnyKey(v.to_string()))
            }
            fn visit_u64<E>(self, v: u64) -> std::result::Result<AnyKey, E> {
                Ok(AnyKey(v.to_string()))
            }
            fn visit_f64<E>(self, v: f64) -> std::result::Result<AnyKey, E> {
                Ok(AnyKey(v.to_string()))
            }
            fn visit_bool<E>(self, v: bool) -> std::result::Result<AnyKey, E> {
                Ok(AnyKey(v.to_string()))
            }
        }
        d.deserialize_any(V)
    }
}

impl<'de> Visitor<'de> for SeekVisitor<'_> {
    type Value = ();
    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("any value")
    }
    fn visit_bool<E: de::Error>(self, _: bool) -> std::result::Result<(), E> {
        self.leaf()
    }
    fn visit_i64<E: de::Error>(self, _: i64) -> std::result::Result<(), E> {
        self.leaf()
    }
    fn visit_u64<E: de::Error>(self, _: u64) -> std::result::Result<(), E> {
        self.leaf()
    }
    fn visit_f64<E: de::Error>(self, _: f64) -> std::result::Result<(), E> {
        self.leaf()
    }
    fn visit_str<E: de::Error>(self, _: &str) -> std::result::Result<(), E> {
        self.leaf()
    }
    fn visit_unit<E: de::Error>(self) -> std::result::Result<(), E> {
        self.leaf()
    }
    fn visit_none<E: de::Error>(self) -> std::result::Result<(), E> {
        self.leaf()
    }
    fn visit_some<D: de::Deserializer<'de>>(self, d: D) -> std::result::Result<(), D::Error> {
        d.deserialize_any(self)
    }
    fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> std::result::Result<(), A::Error> {
        if self.0.is_empty() {
            return Err(de::Error::custom(FOUND));
        }
        while let Some(AnyKey(k)) = map.next_key::<AnyKey>()? {
            if self.0[0] == Seg::Key(k) {
                map.next_value_seed(Seek(&self.0[1..]))?;
            } else {
                map.next_value::<IgnoredAny>()?;
            }
        }
        Ok(())
    }
    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> std::result::Result<(), A::Error> {
        if self.0.is_empty() {
            return Err(de::Error::custom(FOUND));
        }
        let mut i = 0;
        loop {
            let found = if self.0[0] == Seg::Index(i) {
                seq.next_element_seed(Seek(&self.0[1..]))?
            } else {
                seq.next_element::<IgnoredAny>()?.map(|_| ())
            };
            if found.is_none() {
                return Ok(());
            }
            i += 1;
        }
    }
}

/// Sets the value at a dotted key path (`platform.altitude_m`) in a YAML tree, making the
/// sections on the way that do not exist yet (a sweep's or the bench's overrides).
pub fn set_path(
    tree: &mut serde_yaml::Value,
    key: &str,
    value: serde_yaml::Value,
) -> std::result::Result<(), String> {
    let mut node = tree;
    let parts: Vec<&str> = key.split('.').collect();
    for (i, p) in parts.iter().enumerate() {
        let map = node
            .as_mapping_mut()
            .ok_or_else(|| format!("`{}` is not a section", parts[..i].join(".")))?;
        let k = serde_yaml::Value::String(p.to_string());
        if i + 1 == parts.len() {
            map.insert(k, value);
            return Ok(());
        }
        node = map
            .entry(k)
            .or_insert_with(|| serde_yaml::Value::Mapping(Default::default()));
    }
    Err("empty key".into())
}

/// A value on one line, for messages and `sweep.csv`: a scalar as YAML writes it, a list or
/// mapping in JSON's flow style (`{"start_ns":0,"bins":20}`).
pub fn inline(v: &serde_yaml::Value) -> String {
    use serde_yaml::Value;
    let yaml = |v: &Value| {
        serde_yaml::to_string(v)
            .unwrap_or_default()
            .trim()
            .replace('\n', " ")
    };
    match v {
        Value::Sequence(_) | Value::Mapping(_) | Value::Tagged(_) => {
            serde_json::to_string(v).unwrap_or_else(|_| yaml(v))
        }
        v => yaml(v),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const TEXT: &str = "name: a\ninstrument:\n  pulse_energy_j: -1\n  bin_ns: 1\nplatform: { kind: static, pulses: [ { position: [0, 0, 5] }, { position: [1, 2, 3] } ] }\nmaterials:\n  soil: { reflectance: { 532: 0.1 } }\n";

    #[test]
    fn locates_block_and_flow_keys() {
        assert_eq!(locate(TEXT, "instrument.pulse_energy_j"), Some((3, 19)));
        assert_eq!(locate(TEXT, "instrument.bin_ns"), Some((4, 11)));
        assert_eq!(
            locate(TEXT, "platform.pulses[1].position").map(|l| l.0),
            Some(5)
        );
        assert_eq!(
            locate(TEXT, "materials.soil.reflectance.532").map(|l| l.0),
            Some(7)
        );
        // a missing key falls back to its nearest parent
        assert_eq!(
            locate(TEXT, "instrument.nothing"),
            locate(TEXT, "instrument")
        );
    }

    #[test]
    fn serde_types_in_plain_words() {
        #[derive(serde::Deserialize, Debug)]
        #[serde(deny_unknown_fields)]
        #[allow(dead_code)]
        struct T {
            x: f64,
            n: u32,
            b: bool,
            l: Vec<f64>,
        }
        let cases = [
            (
                "x: high\nn: 1\nb: true\nl: []\n",
                "x",
                "expected a number, found \"high\"",
            ),
            (
                "x: 1\nn: -3\nb: true\nl: []\n",
                "n",
                "expected a whole number from 0 to 4294967295, found -3",
            ),
            (
                "x: 1\nn: 2.5\nb: true\nl: []\n",
                "n",
                "expected a whole number from 0 to 4294967295, found 2.5",
            ),
            // a required key left out is named as the key
            (
                "x: 1\nn: 1\nb: true\n",
                "l",
                "required, and missing: add it",
            ),
            // a whole number written with a decimal point is shown with it
            (
                "x: 1\nn: 7.0\nb: true\nl: []\n",
                "n",
                "expected a whole number from 0 to 4294967295, found 7.0",
            ),
            (
                "x: 1\nn: 20000000000\nb: true\nl: []\n",
                "n",
                "expected a whole number from 0 to 4294967295, found 20000000000",
            ),
            (
                "x: 1\nn: 1\nb: 7\nl: []\n",
                "b",
                "expected true or false, found 7",
            ),
            // past u64: serde names the integer "as u128", which is no part of the value
            (
                "x: 1\nn: 18446744073709551616\nb: true\nl: []\n",
                "n",
                "expected a whole number from 0 to 4294967295, found 18446744073709551616",
            ),
            (
                "x: 1\nn: 1\nb: true\nl: { a: 1 }\n",
                "l",
                "expected a list, found a mapping",
            ),
            (
                "x: [1]\nn: 1\nb: true\nl: []\n",
                "x",
                "expected a number, found a list",
            ),
        ];
        for (text, key, want) in cases {
            let e = parse::<T>(Path::new("f.yaml"), text)
                .unwrap_err()
                .to_string();
            assert!(e.contains(&format!("{key}: {want}")), "{text:?}: {e}");
        }
        // a second document is pointed at, not said unsupported
        let e = parse::<T>(
            Path::new("f.yaml"),
            "---\nx: 1\nn: 1\nb: true\nl: []\n---\nx: 2\n",
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.starts_with("f.yaml:6:1:") && e.contains("second YAML document"),
            "{e}"
        );
        // a message of our own passes unchanged
        assert_eq!(plain_words("unknown field `q`"), "unknown field `q`");
        // a key given twice in a mapping is refused where it stands, not silently replaced
        let text = "materials:\n  bark: 1\n  leaf: 2\n  bark: 3\n";
        let e =
            parse::<std::collections::BTreeMap<String, std::collections::BTreeMap<String, f64>>>(
                Path::new("f.yaml"),
                text,
            )
            .unwrap_err()
            .to_string();
        assert_eq!(
            e,
            "f.yaml:4:3: bark: given twice in the same mapping: keep one"
        );
    }
}
