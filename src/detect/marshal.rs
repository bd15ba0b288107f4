//! Reads a detector's output from CPython's `marshal` format (version 4) into JSON values.
//!
//! The worker encodes what `find_pattern` returned with `marshal.dumps(out, 4)`, which runs in C and
//! writes floats as raw doubles: for the float-heavy outputs of detectors it is 10–30× cheaper than
//! `json.dumps` plus the bounded walk that guarded it (see `docs/performance.md`). Outputs marshal
//! refuses (subclasses of dict or list, such as the trace's own read-only dicts) still travel as JSON.
//!
//! The reader accepts exactly what JSON can say — `None`, booleans, integers, finite floats, strings,
//! lists, tuples (read as lists) and dicts whose keys are strings, integers, booleans or `None` (turned
//! into strings as `json.dumps` does) — and refuses anything else (sets, bytes, complex numbers, code,
//! `...`, NaN and infinities, float keys) with the JSON path of the offending value, since the repair
//! prompt shows that error to the model that wrote the detector. Version 4 shares repeated objects by
//! reference, so a small message can stand for a huge value (`[s] * 100` with a 1 MB `s`); the reader
//! charges every value it produces against a byte budget and refuses the output when it runs out,
//! before allocating it. Nesting is bounded as well.

use serde_json::{Map, Number, Value};

/// Deepest nesting accepted (serde_json's own parser stops at 128 as well).
pub const MAX_DEPTH: usize = 128;

/// Why an output was refused: where (a JSON path, `$` is the whole output) and what.
#[derive(Clone, Debug, PartialEq)]
pub struct OutputError {
    /// JSON path of the offending value, as in `$[2].parameters.object_details`.
    pub path: String,
    /// What is wrong with it.
    pub message: String,
}

/// Decodes one marshalled value, charging its JSON-like size against `budget` bytes (each value one
/// byte, strings and keys their length, containers one byte per item; an under-estimate of its JSON
/// text, so an output that fits as JSON is never refused).
pub fn decode(bytes: &[u8], budget: usize) -> Result<Value, OutputError> {
    let mut r = Reader {
        bytes,
        pos: 0,
        refs: Vec::new(),
        replay: 0,
        budget,
        limit: budget,
    };
    let mut path = Vec::new();
    let v = r.value(0, &mut path)?;
    if r.pos != bytes.len() {
        return Err(r.fail(&path, "trailing bytes after the output"));
    }
    Ok(v)
}

// Type codes (CPython's Python/marshal.c).
const NULL: u8 = b'0';
const NONE: u8 = b'N';
const FALSE: u8 = b'F';
const TRUE: u8 = b'T';
const INT: u8 = b'i';
const LONG: u8 = b'l';
const BINARY_FLOAT: u8 = b'g';
const REF: u8 = b'r';
const TUPLE: u8 = b'(';
const SMALL_TUPLE: u8 = b')';
const LIST: u8 = b'[';
const DICT: u8 = b'{';
const UNICODE: u8 = b'u';
const INTERNED: u8 = b't';
const ASCII: u8 = b'a';
const ASCII_INTERNED: u8 = b'A';
const SHORT_ASCII: u8 = b'z';
const SHORT_ASCII_INTERNED: u8 = b'Z';
const FLAG_REF: u8 = 0x80;

/// A value flagged for sharing. Scalars and strings are kept; a container is kept as the position of
/// its type byte and read again for each reference, so that the common case (the writer flags the
/// whole output, which its caller also holds) costs nothing.
enum Shared {
    /// A container still being read (a reference to it is a cycle).
    Open,
    /// A container, read again from this byte offset.
    At(usize),
    /// A scalar or string.
    Value(Value),
}

/// One step of a JSON path.
enum Seg {
    Index(usize),
    Key(String),
}

struct Reader<'a> {
    bytes: &'a [u8],
    pos: usize,
    /// Values flagged for sharing, by reference index.
    refs: Vec<Shared>,
    /// Above zero while a shared container is read again for a reference: nothing is registered then.
    replay: usize,
    budget: usize,
    limit: usize,
}

fn render(path: &[Seg]) -> String {
    let mut s = String::from("$");
    for seg in path {
        match seg {
            Seg::Index(i) => s.push_str(&format!("[{i}]")),
            Seg::Key(k) => {
                if !k.is_empty() && k.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') {
                    s.push('.');
                    s.push_str(k);
                } else {
                    s.push_str(&format!("[{}]", Value::String(k.clone())));
                }
            }
        }
    }
    s
}

/// The Python type a marshal code stands for, for error messages.
fn python_type(code: u8) -> &'static str {
    match code {
        b'<' => "set",
        b'>' => "frozenset",
        b's' => "bytes",
        b'x' | b'y' => "complex",
        b'c' => "code",
        b'.' => "ellipsis",
        b'S' => "StopIteration",
        _ => "unknown",
    }
}

impl Reader<'_> {
    fn fail(&self, path: &[Seg], message: impl Into<String>) -> OutputError {
        OutputError {
            path: render(path),
            message: message.into(),
        }
    }

    fn charge(&mut self, n: usize) -> Result<(), OutputError> {
        match self.budget.checked_sub(n) {
            Some(rest) => {
                self.budget = rest;
                Ok(())
            }
            None => Err(OutputError {
                path: "$".into(),
                message: format!(
                    "the output is over {} bytes (limit {})",
                    self.limit, self.limit
                ),
            }),
        }
    }

    fn take(&mut self, n: usize, path: &[Seg]) -> Result<&[u8], OutputError> {
        let end = self
            .pos
            .checked_add(n)
            .filter(|&e| e <= self.bytes.len())
            .ok_or_else(|| self.fail(path, "the output ends early (truncated message)"))?;
        let s = &self.bytes[self.pos..end];
        self.pos = end;
        Ok(s)
    }

    fn u8(&mut self, path: &[Seg]) -> Result<u8, OutputError> {
        Ok(self.take(1, path)?[0])
    }

    fn i32(&mut self, path: &[Seg]) -> Result<i32, OutputError> {
        let b = self.take(4, path)?;
        Ok(i32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    }

    fn len(&mut self, path: &[Seg]) -> Result<usize, OutputError> {
        let n = self.i32(path)?;
        usize::try_from(n).map_err(|_| self.fail(path, "negative length in the output"))
    }

    fn string(&mut self, n: usize, path: &[Seg]) -> Result<String, OutputError> {
        self.charge(n)?;
        let b = self.take(n, path)?;
        match std::str::from_utf8(b) {
            Ok(s) => Ok(s.to_owned()),
            Err(_) => Err(self.fail(
                path,
                "a string holds a lone surrogate, which JSON text cannot carry",
            )),
        }
    }

    /// Reads one value (and registers it when flagged for sharing).
    fn value(&mut self, depth: usize, path: &mut Vec<Seg>) -> Result<Value, OutputError> {
        if depth > MAX_DEPTH {
            return Err(self.fail(
                path,
                format!("the output is nested deeper than {MAX_DEPTH} levels"),
            ));
        }
        let at = self.pos;
        let code = self.u8(path)?;
        let flagged = code & FLAG_REF != 0 && self.replay == 0;
        let code = code & !FLAG_REF;
        // A container's reference index is taken before its items are read, as the writer assigns it.
        let slot = if flagged && matches!(code, TUPLE | SMALL_TUPLE | LIST | DICT) {
            self.refs.push(Shared::Open);
            Some(self.refs.len() - 1)
        } else {
            None
        };
        self.charge(1)?;
        let v = match code {
            NONE => Value::Null,
            FALSE => Value::Bool(false),
            TRUE => Value::Bool(true),
            INT => Value::from(self.i32(path)?),
            LONG => self.long(path)?,
            BINARY_FLOAT => self.float(path)?,
            UNICODE | INTERNED | ASCII | ASCII_INTERNED => {
                let n = self.len(path)?;
                Value::String(self.string(n, path)?)
            }
            SHORT_ASCII | SHORT_ASCII_INTERNED => {
                let n = self.u8(path)? as usize;
                Value::String(self.string(n, path)?)
            }
            TUPLE | LIST | SMALL_TUPLE => self.sequence(code == SMALL_TUPLE, depth, path)?,
            DICT => self.dict(depth, path)?,
            REF => return self.reference(depth, path),
            other => {
                return Err(self.fail(
                    path,
                    format!(
                        "a value of type {} is not JSON (use dict, list, str, int, float, bool, None)",
                        python_type(other)
                    ),
                ));
            }
        };
        match slot {
            Some(i) => self.refs[i] = Shared::At(at),
            None if flagged => self.refs.push(Shared::Value(v.clone())),
            None => {}
        }
        Ok(v)
    }

    /// A float (8 bytes, little-endian); NaN and infinities are refused.
    fn float(&mut self, path: &[Seg]) -> Result<Value, OutputError> {
        let b = self.take(8, path)?;
        let f = f64::from_le_bytes(b.try_into().expect("8 bytes"));
        match Number::from_f64(f) {
            Some(n) => Ok(Value::Number(n)),
            None => Err(self.fail(
                path,
                format!("{f} is not a JSON number (NaN and infinities are not allowed)"),
            )),
        }
    }

    /// A tuple or list (its length a byte for a small tuple, else 4 bytes), as a JSON array.
    fn sequence(
        &mut self,
        small: bool,
        depth: usize,
        path: &mut Vec<Seg>,
    ) -> Result<Value, OutputError> {
        let n = if small {
            self.u8(path)? as usize
        } else {
            self.len(path)?
        };
        self.charge(n)?;
        // Every item takes at least one byte, so a length beyond the message is a lie.
        let mut items = Vec::with_capacity(n.min(self.bytes.len() - self.pos));
        for i in 0..n {
            path.push(Seg::Index(i));
            items.push(self.value(depth + 1, path)?);
            path.pop();
        }
        Ok(Value::Array(items))
    }

    /// A dict: key, value pairs up to a `NULL` byte.
    fn dict(&mut self, depth: usize, path: &mut Vec<Seg>) -> Result<Value, OutputError> {
        let mut map = Map::new();
        loop {
            if self.bytes.get(self.pos) == Some(&NULL) {
                self.pos += 1;
                break;
            }
            let key = self.key(depth, path)?;
            self.charge(1 + key.len())?;
            path.push(Seg::Key(key));
            let item = self.value(depth + 1, path)?;
            let Some(Seg::Key(key)) = path.pop() else {
                unreachable!("pushed a key")
            };
            map.insert(key, item);
        }
        Ok(Value::Object(map))
    }

    /// A reference to a shared value read before: a copy of it (charged again, as JSON repeats
    /// it), or a container read again from where it started; a reference to a container still
    /// being read is a cycle.
    fn reference(&mut self, depth: usize, path: &mut Vec<Seg>) -> Result<Value, OutputError> {
        let i = self.len(path)?;
        match self.refs.get(i) {
            Some(Shared::Value(v)) => {
                let v = v.clone();
                self.charge(size(&v, self.budget.saturating_add(1)))?;
                Ok(v)
            }
            Some(&Shared::At(start)) => {
                let resume = self.pos;
                self.pos = start;
                self.replay += 1;
                let v = self.value(depth, path);
                self.replay -= 1;
                self.pos = resume;
                v
            }
            Some(Shared::Open) => Err(self.fail(path, "the output contains itself (a cycle)")),
            None => Err(self.fail(path, "a reference to nothing (corrupt message)")),
        }
    }

    /// A dict key as JSON has it: strings as they are; integers, booleans and `None` as `json.dumps`
    /// writes them.
    fn key(&mut self, depth: usize, path: &mut Vec<Seg>) -> Result<String, OutputError> {
        let at = self.pos;
        let k = self.value(depth + 1, path)?;
        match k {
            Value::String(s) => Ok(s),
            Value::Bool(b) => Ok(b.to_string()),
            Value::Null => Ok("null".into()),
            Value::Number(n) if n.is_i64() || n.is_u64() => Ok(n.to_string()),
            _ => {
                let code = self.bytes[at] & !FLAG_REF;
                let what = match code {
                    BINARY_FLOAT => "a float",
                    TUPLE | SMALL_TUPLE => "a tuple",
                    LONG => "an integer too large for JSON",
                    _ => "not a string",
                };
                Err(self.fail(
                    path,
                    format!("a dict key is {what}; keys must be strings (or integers)"),
                ))
            }
        }
    }

    /// A Python int of more than 32 bits: 15-bit digits, least significant first; the count's sign is
    /// the number's. Values beyond 64 bits become floats, as serde_json reads such JSON numbers.
    fn long(&mut self, path: &[Seg]) -> Result<Value, OutputError> {
        let n = self.i32(path)?;
        let digits = n.unsigned_abs() as usize;
        let raw = self.take(2 * digits, path)?;
        let mut mag: f64 = 0.0;
        let mut exact: Option<u128> = Some(0);
        for i in (0..digits).rev() {
            let d = u16::from_le_bytes([raw[2 * i], raw[2 * i + 1]]);
            if d >= 1 << 15 {
                return Err(self.fail(path, "a corrupt integer in the output"));
            }
            mag = mag * 32768.0 + f64::from(d);
            exact = exact
                .and_then(|e| e.checked_mul(32768))
                .and_then(|e| e.checked_add(u128::from(d)));
        }
        let v = match (exact, n < 0) {
            (Some(e), false) if e <= u128::from(u64::MAX) => Value::from(e as u64),
            (Some(e), true) if e <= 1u128 << 63 => Value::from((e as i128).wrapping_neg() as i64),
            _ => {
                let f = if n < 0 { -mag } else { mag };
                match Number::from_f64(f) {
                    Some(x) => Value::Number(x),
                    None => return Err(self.fail(path, "an integer too large for JSON")),
                }
            }
        };
        Ok(v)
    }
}

/// The size [`decode`] charges for `v`, counted no further than `cap`.
fn size(v: &Value, cap: usize) -> usize {
    // Most shared values are strings (dict keys, labels) and numbers: no walk for those.
    match v {
        Value::String(s) => return (1 + s.len()).min(cap),
        Value::Array(_) | Value::Object(_) => {}
        _ => return 1.min(cap),
    }
    let mut used = 0usize;
    let mut stack = vec![v];
    while let Some(v) = stack.pop() {
        used += 1;
        match v {
            Value::String(s) => used += s.len(),
            Value::Array(a) => {
                used += a.len();
                stack.extend(a.iter());
            }
            Value::Object(m) => {
                for (k, item) in m {
                    used += 1 + k.len();
                    stack.push(item);
                }
            }
            _ => {}
        }
        if used >= cap {
            return cap;
        }
    }
    used
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    /// Marshal bytes as CPython 3.11 writes them (`marshal.dumps(x, 4)`), spelled out by hand.
    fn ascii(s: &str) -> Vec<u8> {
        let mut b = vec![SHORT_ASCII, s.len() as u8];
        b.extend_from_slice(s.as_bytes());
        b
    }

    fn list(items: &[Vec<u8>]) -> Vec<u8> {
        let mut b = vec![LIST];
        b.extend_from_slice(&(items.len() as i32).to_le_bytes());
        for i in items {
            b.extend_from_slice(i);
        }
        b
    }

    fn int(i: i32) -> Vec<u8> {
        let mut b = vec![INT];
        b.extend_from_slice(&i.to_le_bytes());
        b
    }

    fn float(f: f64) -> Vec<u8> {
        let mut b = vec![BINARY_FLOAT];
        b.extend_from_slice(&f.to_le_bytes());
        b
    }

    fn dict(pairs: &[(Vec<u8>, Vec<u8>)]) -> Vec<u8> {
        let mut b = vec![DICT];
        for (k, v) in pairs {
            b.extend_from_slice(k);
            b.extend_from_slice(v);
        }
        b.push(NULL);
        b
    }

    #[test]
    fn scalars_containers_and_keys_read_as_json_does() {
        let bytes = list(&[
            dict(&[
                (ascii("label"), ascii("x")),
                (ascii("start_timestep"), int(3)),
                (int(7), float(0.25)),
                (vec![TRUE], vec![NONE]),
                (vec![NONE], vec![SMALL_TUPLE, 2, FALSE, TRUE]),
            ]),
            {
                // 2**40 as a long: three 15-bit digits (0, 0, 1024).
                let mut b = vec![LONG];
                b.extend_from_slice(&3i32.to_le_bytes());
                for d in [0u16, 0, 1024] {
                    b.extend_from_slice(&d.to_le_bytes());
                }
                b
            },
            {
                let mut b = vec![UNICODE];
                let s = "é";
                b.extend_from_slice(&(s.len() as i32).to_le_bytes());
                b.extend_from_slice(s.as_bytes());
                b
            },
        ]);
        let v = decode(&bytes, 1 << 20).unwrap();
        assert_eq!(
            v,
            json!([{"label": "x", "start_timestep": 3, "7": 0.25, "true": null, "null": [false, true]}, 1u64 << 40, "é"])
        );
    }

    #[test]
    fn shared_values_are_copied_and_charged_each_time() {
        // [s, s] where s is flagged for sharing, then referenced.
        let mut s = ascii("abcdef");
        s[0] |= FLAG_REF;
        let mut r = vec![REF];
        r.extend_from_slice(&0i32.to_le_bytes());
        let bytes = list(&[s, r.clone(), r]);
        assert_eq!(
            decode(&bytes, 1000).unwrap(),
            json!(["abcdef", "abcdef", "abcdef"])
        );
        // The same message under a budget that holds one copy but not three.
        let e = decode(&bytes, 12).unwrap_err();
        assert_eq!(e.path, "$");
        assert!(e.message.contains("limit 12"), "{}", e.message);
    }

    #[test]
    fn shared_containers_are_read_again_and_cycles_refused() {
        // [inner, inner] where inner = [1, "a"] is flagged (index 0), then referenced.
        let mut inner = list(&[int(1), ascii("a")]);
        inner[0] |= FLAG_REF;
        let mut r = vec![REF];
        r.extend_from_slice(&0i32.to_le_bytes());
        assert_eq!(
            decode(&list(&[inner, r.clone()]), 1000).unwrap(),
            json!([[1, "a"], [1, "a"]])
        );
        // A list that holds itself (index 0 referenced from inside).
        let mut cyclic = list(&[r]);
        cyclic[0] |= FLAG_REF;
        let e = decode(&cyclic, 1000).unwrap_err();
        assert!(e.message.contains("cycle"), "{}", e.message);
        // Nested sharing that doubles at every level: level k = [level k+1, ref(level k+1)], the
        // innermost [None, None]; 2^40 values as JSON, refused once the budget is spent.
        let depth: i32 = 40;
        let mut bytes = Vec::new();
        for _ in 0..depth {
            bytes.extend_from_slice(&[LIST | FLAG_REF, 2, 0, 0, 0]);
        }
        bytes.extend_from_slice(&[NONE, NONE]);
        for level in (0..depth - 1).rev() {
            bytes.push(REF);
            bytes.extend_from_slice(&(level + 1).to_le_bytes());
        }
        let e = decode(&bytes, 1 << 16).unwrap_err();
        assert!(e.message.contains("limit"), "{}", e.message);
        // The same with three levels fits: [[[None, None], [None, None]], ...].
        let mut small = Vec::new();
        for _ in 0..3 {
            small.extend_from_slice(&[LIST | FLAG_REF, 2, 0, 0, 0]);
        }
        small.extend_from_slice(&[NONE, NONE]);
        for level in (0..2i32).rev() {
            small.push(REF);
            small.extend_from_slice(&(level + 1).to_le_bytes());
        }
        let pair = json!([null, null]);
        let two = json!([pair.clone(), pair]);
        assert_eq!(decode(&small, 1 << 16).unwrap(), json!([two.clone(), two]));
    }

    #[test]
    fn what_json_cannot_say_is_refused_with_its_path() {
        let set = {
            let mut b = vec![b'<'];
            b.extend_from_slice(&1i32.to_le_bytes());
            b.extend_from_slice(&int(1));
            b
        };
        let e = decode(&list(&[dict(&[(ascii("p"), set)])]), 1 << 20).unwrap_err();
        assert_eq!(e.path, "$[0].p");
        assert!(e.message.contains("set"), "{}", e.message);
        let e = decode(&list(&[float(f64::NAN)]), 1 << 20).unwrap_err();
        assert_eq!(e.path, "$[0]");
        assert!(e.message.contains("NaN"), "{}", e.message);
        let e = decode(&dict(&[(float(1.5), int(1))]), 1 << 20).unwrap_err();
        assert!(e.message.contains("float"), "{}", e.message);
        let e = decode(&dict(&[(ascii("a b"), vec![b's', 0, 0, 0, 0])]), 1 << 20).unwrap_err();
        assert_eq!(e.path, "$[\"a b\"]");
        assert!(e.message.contains("bytes"), "{}", e.message);
    }

    #[test]
    fn corrupt_or_hostile_messages_are_errors_not_panics() {
        // Truncated, a huge claimed length, a reference to nothing, nesting past the bound.
        assert!(decode(&[LIST, 5, 0, 0], 100).is_err());
        assert!(decode(&[LIST, 0xff, 0xff, 0xff, 0x7f], 100).is_err());
        assert!(decode(&[REF, 0, 0, 0, 0], 100).is_err());
        let mut deep = Vec::new();
        for _ in 0..(MAX_DEPTH + 2) {
            deep.extend_from_slice(&[LIST, 1, 0, 0, 0]);
        }
        deep.push(NONE);
        let e = decode(&deep, 1 << 20).unwrap_err();
        assert!(e.message.contains("nested"), "{}", e.message);
        // Every prefix of a valid message fails cleanly.
        let ok = list(&[dict(&[(ascii("k"), float(1.0))]), int(2)]);
        for n in 0..ok.len() {
            assert!(decode(&ok[..n], 100).is_err());
        }
        assert!(decode(&ok, 100).is_ok());
    }
}
