//! MesaTask's `sbert_text_features.pkl` read and written without Python: `{"uids": [str, ...],
//! "text_features": numpy array N×D}` (float16 or float32).
//!
//! Why a hand-written reader: a pickle is a program for a stack machine whose `GLOBAL` and
//! `REDUCE` opcodes import and call any function the file names (`os.system`,
//! `builtins.eval`). The Rust pickle crates either do not understand numpy's reduce protocol
//! (`serde-pickle` refuses every global, so it cannot read an ndarray at all) or evaluate
//! globals through Python. This reader is a stack machine of its own over the opcodes that
//! Python's pickle protocols 2–5 use for exactly these objects, and it *recognises* a fixed
//! list of globals, which it implements natively, instead of importing anything:
//!
//! - `numpy.core.multiarray._reconstruct` / `numpy._core.multiarray._reconstruct` with
//!   `numpy.ndarray`, then `BUILD` with `(1, shape, dtype, is_fortran, raw bytes)`: how numpy
//!   1.x and 2.x pickle an array at protocols 2–4 (and at 5 when it is not contiguous);
//! - `numpy.core.numeric._frombuffer` / `numpy._core.numeric._frombuffer` with an in-band
//!   buffer (`BYTEARRAY8`, or bytes), the dtype, the shape and the order: protocol 5;
//! - `numpy.dtype` with `('f2'|'f4', False, True)` and its `BUILD` state (byte order);
//! - `_codecs.encode(str, 'latin1')`: how protocol 2 writes Python 3 `bytes`.
//!
//! Any other global is refused before anything is built, naming it ([`PickleError::Global`]).
//! Out-of-band buffers (`NEXT_BUFFER`) are refused: the file alone must hold the data.
//! Every length is checked against what is left of the input, so a truncated or malformed file
//! is an error, never a panic, and memory stays proportional to the input's size (the caller
//! bounds that).
//!
//! [`write_text_features`] writes protocol 4 (what MesaTask's `compress_pickle.load` and
//! Python's `pickle.load` read), with numpy 1.x's global names, which numpy 2.x also resolves.

use std::collections::HashMap;

use thiserror::Error;

/// What went wrong reading a pickle; the caller adds the file name.
#[derive(Debug, Error, PartialEq)]
pub enum PickleError {
    /// A global that this reader does not implement: the file would run code under Python.
    #[error(
        "names the global `{0}`, which is refused: only numpy's array and dtype \
         reconstruction and `_codecs.encode` are read (no code from a pickle is ever run; \
         re-save the features as {{\"uids\": [...], \"text_features\": numpy array}})"
    )]
    Global(String),
    /// The input ends inside an opcode or before `STOP`.
    #[error("is truncated at byte {0} (re-copy the file)")]
    Truncated(usize),
    /// An opcode outside protocols 2–5's subset for these objects.
    #[error("opcode 0x{opcode:02x} at byte {offset} is not read (expected a pickle of {{\"uids\", \"text_features\"}} at protocol 2–5)")]
    Opcode {
        /// The opcode byte.
        opcode: u8,
        /// Its offset.
        offset: usize,
    },
    /// A well-formed opcode used on the wrong kind of value, or an unexpected structure.
    #[error("byte {offset}: {problem}")]
    Malformed {
        /// Offset of the opcode.
        offset: usize,
        /// What is wrong.
        problem: String,
    },
    /// The unpickled object is not the expected dict.
    #[error("{0}")]
    Content(String),
}

/// The element type of the features.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FloatKind {
    /// numpy float16.
    F16,
    /// numpy float32.
    F32,
}

impl FloatKind {
    /// Bytes per element.
    pub fn width(self) -> usize {
        match self {
            FloatKind::F16 => 2,
            FloatKind::F32 => 4,
        }
    }

    /// The numpy type string (`f2`, `f4`).
    pub fn numpy(self) -> &'static str {
        match self {
            FloatKind::F16 => "f2",
            FloatKind::F32 => "f4",
        }
    }
}

/// The features of `sbert_text_features.pkl`: one row per uid, little-endian, C order.
#[derive(Debug, Clone, PartialEq)]
pub struct TextFeatures {
    /// The uid of each row.
    pub uids: Vec<String>,
    /// The element type, as the pickle had it.
    pub kind: FloatKind,
    /// Number of columns (768 for all-mpnet-base-v2).
    pub cols: usize,
    /// `uids.len() × cols` elements, little-endian bytes in C order.
    pub data_le: Vec<u8>,
}

impl TextFeatures {
    /// The features as a `.npy` file (version 1.0, `<f2`/`<f4`, C order): the bytes are those
    /// of the pickle, so the values are bit for bit what numpy wrote.
    pub fn to_npy(&self) -> Vec<u8> {
        let header = format!(
            "{{'descr': '<{}', 'fortran_order': False, 'shape': ({}, {}), }}",
            self.kind.numpy(),
            self.uids.len(),
            self.cols
        );
        // Magic (6) + version (2) + length (2) + header + '\n', padded to 64 bytes.
        let unpadded = 10 + header.len() + 1;
        let pad = (64 - unpadded % 64) % 64;
        let mut out = Vec::with_capacity(unpadded + pad + self.data_le.len());
        out.extend_from_slice(b"\x93NUMPY\x01\x00");
        let len = (header.len() + pad + 1) as u16;
        out.extend_from_slice(&len.to_le_bytes());
        out.extend_from_slice(header.as_bytes());
        out.extend(std::iter::repeat_n(b' ', pad));
        out.push(b'\n');
        out.extend_from_slice(&self.data_le);
        out
    }
}

impl TextFeatures {
    /// Reads a `.npy` file of [`TextFeatures::to_npy`]'s form (version 1.0 to 3.0, a 2-D
    /// `<f2`/`<f4` array in C order) with the uid of each row; `Err` says what is wrong.
    pub fn from_npy(bytes: &[u8], uids: Vec<String>) -> Result<Self, String> {
        let magic = bytes.get(..8).ok_or("shorter than a .npy header")?;
        if &magic[..6] != b"\x93NUMPY" {
            return Err("not a .npy file (no \\x93NUMPY magic)".into());
        }
        let (len, start) = match magic[6] {
            1 => (
                usize::from(u16::from_le_bytes([
                    *bytes.get(8).ok_or("truncated header")?,
                    *bytes.get(9).ok_or("truncated header")?,
                ])),
                10,
            ),
            2 | 3 => {
                let b = bytes.get(8..12).ok_or("truncated header")?;
                (u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize, 12)
            }
            v => return Err(format!(".npy version {v} (expected 1 to 3)")),
        };
        let header = bytes.get(start..start + len).ok_or("truncated header")?;
        let header = std::str::from_utf8(header).map_err(|_| "header is not text")?;
        let compact: String = header.chars().filter(|c| !c.is_whitespace()).collect();
        let kind = if compact.contains("'descr':'<f2'") {
            FloatKind::F16
        } else if compact.contains("'descr':'<f4'") {
            FloatKind::F32
        } else {
            return Err(format!("dtype in {header:?} (expected '<f2' or '<f4')"));
        };
        if !compact.contains("'fortran_order':False") {
            return Err("Fortran order (expected C order)".into());
        }
        let shape = compact
            .split("'shape':(")
            .nth(1)
            .and_then(|rest| rest.split(')').next())
            .ok_or("no shape")?;
        let dims: Vec<usize> = shape
            .split(',')
            .filter(|d| !d.is_empty())
            .map(|d| d.parse::<usize>().map_err(|_| format!("shape ({shape})")))
            .collect::<Result<_, _>>()?;
        let [rows, cols] = dims[..] else {
            return Err(format!("shape ({shape}) (expected 2 dimensions)"));
        };
        if rows != uids.len() {
            return Err(format!("{rows} rows for {} uids", uids.len()));
        }
        let data = &bytes[start + len..];
        let needed = rows
            .checked_mul(cols)
            .and_then(|n| n.checked_mul(kind.width()))
            .ok_or("shape overflows")?;
        if data.len() != needed {
            return Err(format!(
                "{} data bytes, the shape needs {needed}",
                data.len()
            ));
        }
        Ok(Self {
            uids,
            kind,
            cols,
            data_le: data.to_vec(),
        })
    }
}

/// A numpy dtype as this reader knows it.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Dtype {
    kind: FloatKind,
    big_endian: bool,
}

/// The globals this reader implements.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Global {
    Reconstruct,
    FromBuffer,
    NdarrayType,
    DtypeType,
    CodecsEncode,
}

fn lookup_global(module: &str, name: &str) -> Result<Global, PickleError> {
    Ok(match (module, name) {
        ("numpy.core.multiarray" | "numpy._core.multiarray", "_reconstruct") => Global::Reconstruct,
        ("numpy.core.numeric" | "numpy._core.numeric", "_frombuffer") => Global::FromBuffer,
        ("numpy", "ndarray") => Global::NdarrayType,
        ("numpy", "dtype") => Global::DtypeType,
        ("_codecs", "encode") => Global::CodecsEncode,
        _ => return Err(PickleError::Global(format!("{module}.{name}"))),
    })
}

/// At most this many values are built: memory stays bounded whatever the opcodes (a value
/// takes about 50 bytes, so 200 MB at most, besides the strings and bytes the input holds).
const MAX_OBJECTS: usize = 4_000_000;

/// An array: shape and bytes in the file's order and byte order.
#[derive(Debug, Clone, PartialEq)]
struct Array {
    shape: Vec<usize>,
    dtype: Dtype,
    fortran: bool,
    data: Vec<u8>,
}

/// A value on the stack or in the memo: an index into the arena for the mutable ones (list,
/// dict, array being built), so that memo references see later appends as Python's do.
#[derive(Debug, Clone, PartialEq)]
enum Obj {
    None,
    Bool(bool),
    Int(i64),
    Str(String),
    Bytes(Vec<u8>),
    Tuple(Vec<usize>),
    List(Vec<usize>),
    Dict(Vec<(usize, usize)>),
    Global(Global),
    Dtype(Option<Dtype>, Option<FloatKind>),
    /// `_reconstruct(ndarray, (0,), b'b')`, waiting for its `BUILD`.
    EmptyArray,
    Array(Array),
}

struct Machine<'a> {
    input: &'a [u8],
    pos: usize,
    arena: Vec<Obj>,
    stack: Vec<usize>,
    marks: Vec<usize>,
    memo: HashMap<u32, usize>,
    op_at: usize,
}

impl<'a> Machine<'a> {
    fn take(&mut self, n: usize) -> Result<&'a [u8], PickleError> {
        let end = self
            .pos
            .checked_add(n)
            .filter(|&end| end <= self.input.len())
            .ok_or(PickleError::Truncated(self.input.len()))?;
        let slice = &self.input[self.pos..end];
        self.pos = end;
        Ok(slice)
    }

    fn u8(&mut self) -> Result<u8, PickleError> {
        Ok(self.take(1)?[0])
    }

    fn le<const N: usize>(&mut self) -> Result<[u8; N], PickleError> {
        let mut out = [0u8; N];
        out.copy_from_slice(self.take(N)?);
        Ok(out)
    }

    fn len_u64(&mut self) -> Result<usize, PickleError> {
        let n = u64::from_le_bytes(self.le::<8>()?);
        // Longer than the input is truncation whatever the platform's usize.
        usize::try_from(n).map_err(|_| PickleError::Truncated(self.input.len()))
    }

    fn line(&mut self) -> Result<&'a str, PickleError> {
        let rest = &self.input[self.pos..];
        let end = rest
            .iter()
            .position(|&b| b == b'\n')
            .ok_or(PickleError::Truncated(self.input.len()))?;
        let line = &rest[..end];
        self.pos += end + 1;
        std::str::from_utf8(line).map_err(|_| self.bad("a GLOBAL line is not UTF-8"))
    }

    fn bad(&self, problem: impl Into<String>) -> PickleError {
        PickleError::Malformed {
            offset: self.op_at,
            problem: problem.into(),
        }
    }

    fn push(&mut self, obj: Obj) -> Result<(), PickleError> {
        if self.arena.len() >= MAX_OBJECTS {
            return Err(self.bad(format!(
                "more than {MAX_OBJECTS} objects (a features file of 15,000 uids holds about \
                 15,100)"
            )));
        }
        self.arena.push(obj);
        self.stack.push(self.arena.len() - 1);
        Ok(())
    }

    fn pop(&mut self) -> Result<usize, PickleError> {
        if self.marks.last().is_some_and(|&m| m >= self.stack.len()) {
            return Err(self.bad("pops past a MARK"));
        }
        self.stack.pop().ok_or_else(|| self.bad("stack underflow"))
    }

    fn top(&self) -> Result<usize, PickleError> {
        self.stack
            .last()
            .copied()
            .ok_or_else(|| self.bad("stack underflow"))
    }

    fn pop_mark(&mut self) -> Result<Vec<usize>, PickleError> {
        let mark = self
            .marks
            .pop()
            .ok_or_else(|| self.bad("no MARK to pop to"))?;
        Ok(self.stack.split_off(mark))
    }

    fn pop_n(&mut self, n: usize) -> Result<Vec<usize>, PickleError> {
        let floor = self.marks.last().copied().unwrap_or(0);
        if self.stack.len() < floor + n {
            return Err(self.bad("stack underflow"));
        }
        Ok(self.stack.split_off(self.stack.len() - n))
    }

    fn memo_put(&mut self, key: u32) -> Result<(), PickleError> {
        let top = self.top()?;
        self.memo.insert(key, top);
        Ok(())
    }

    fn memo_get(&mut self, key: u32) -> Result<(), PickleError> {
        let id = *self
            .memo
            .get(&key)
            .ok_or_else(|| self.bad(format!("memo entry {key} was never stored")))?;
        self.stack.push(id);
        Ok(())
    }

    fn str_of(&self, id: usize) -> Option<&str> {
        match &self.arena[id] {
            Obj::Str(s) => Some(s),
            _ => None,
        }
    }

    fn int_of(&self, id: usize) -> Option<i64> {
        match &self.arena[id] {
            Obj::Int(i) => Some(*i),
            Obj::Bool(b) => Some(i64::from(*b)),
            _ => None,
        }
    }

    fn bytes_of(&self, id: usize) -> Option<&[u8]> {
        match &self.arena[id] {
            Obj::Bytes(b) => Some(b),
            _ => None,
        }
    }

    fn tuple_of(&self, id: usize) -> Option<&[usize]> {
        match &self.arena[id] {
            Obj::Tuple(t) => Some(t),
            _ => None,
        }
    }

    fn shape_of(&self, id: usize) -> Result<Vec<usize>, PickleError> {
        let items = self
            .tuple_of(id)
            .ok_or_else(|| self.bad("an array shape is not a tuple"))?;
        items
            .iter()
            .map(|&i| {
                self.int_of(i)
                    .and_then(|v| usize::try_from(v).ok())
                    .ok_or_else(|| self.bad("an array dimension is not a non-negative integer"))
            })
            .collect()
    }

    fn dtype_of(&self, id: usize) -> Result<Dtype, PickleError> {
        match &self.arena[id] {
            Obj::Dtype(Some(dtype), _) => Ok(*dtype),
            Obj::Dtype(None, _) => Err(self.bad("a dtype was used before its BUILD")),
            _ => Err(self.bad("expected a numpy dtype")),
        }
    }

    fn reduce(&mut self, callable: usize, args: usize) -> Result<Obj, PickleError> {
        let Obj::Global(global) = self.arena[callable] else {
            return Err(self.bad("REDUCE on something that is not a known global"));
        };
        let args: Vec<usize> = self
            .tuple_of(args)
            .ok_or_else(|| self.bad("REDUCE arguments are not a tuple"))?
            .to_vec();
        match global {
            Global::CodecsEncode => {
                let [text, encoding] = args[..] else {
                    return Err(self.bad("_codecs.encode takes (str, 'latin1')"));
                };
                if self.str_of(encoding) != Some("latin1") {
                    return Err(self.bad("_codecs.encode: only the 'latin1' encoding is read"));
                }
                let text = self
                    .str_of(text)
                    .ok_or_else(|| self.bad("_codecs.encode: the text is not a str"))?;
                let bytes = text
                    .chars()
                    .map(|c| u8::try_from(u32::from(c)))
                    .collect::<Result<Vec<u8>, _>>()
                    .map_err(|_| self.bad("_codecs.encode: a character is not latin-1"))?;
                Ok(Obj::Bytes(bytes))
            }
            Global::DtypeType => {
                let (Some(&name), true) = (args.first(), args.len() <= 3) else {
                    return Err(self.bad("numpy.dtype takes (type string, align, copy)"));
                };
                let name = self
                    .str_of(name)
                    .ok_or_else(|| self.bad("numpy.dtype: the type is not a str"))?;
                let kind = match name {
                    "f2" => FloatKind::F16,
                    "f4" => FloatKind::F32,
                    other => {
                        return Err(self.bad(format!(
                            "numpy.dtype '{other}' is not read (expected float16 'f2' or \
                             float32 'f4'; convert with features.astype('float32'))"
                        )))
                    }
                };
                Ok(Obj::Dtype(None, Some(kind)))
            }
            Global::Reconstruct => {
                let [cls, _shape, _typecode] = args[..] else {
                    return Err(self.bad("_reconstruct takes (ndarray, shape, typecode)"));
                };
                if self.arena[cls] != Obj::Global(Global::NdarrayType) {
                    return Err(self.bad("_reconstruct of a class other than numpy.ndarray"));
                }
                Ok(Obj::EmptyArray)
            }
            Global::FromBuffer => {
                let [buffer, dtype, shape, order] = args[..] else {
                    return Err(self.bad("_frombuffer takes (buffer, dtype, shape, order)"));
                };
                let dtype = self.dtype_of(dtype)?;
                let shape = self.shape_of(shape)?;
                let fortran = match self.str_of(order) {
                    Some("C") => false,
                    Some("F") => true,
                    _ => return Err(self.bad("_frombuffer: order is not 'C' or 'F'")),
                };
                let data = self
                    .bytes_of(buffer)
                    .ok_or_else(|| self.bad("_frombuffer: the buffer is not bytes"))?
                    .to_vec();
                self.array(shape, dtype, fortran, data).map(Obj::Array)
            }
            Global::NdarrayType => Err(self.bad("numpy.ndarray is not called directly")),
        }
    }

    fn array(
        &self,
        shape: Vec<usize>,
        dtype: Dtype,
        fortran: bool,
        data: Vec<u8>,
    ) -> Result<Array, PickleError> {
        let needed = shape
            .iter()
            .try_fold(dtype.kind.width(), |acc, &d| acc.checked_mul(d))
            .ok_or_else(|| self.bad("array shape overflows"))?;
        if needed != data.len() {
            return Err(self.bad(format!(
                "array of shape {shape:?} needs {needed} bytes, the pickle holds {}",
                data.len()
            )));
        }
        Ok(Array {
            shape,
            dtype,
            fortran,
            data,
        })
    }

    fn build(&mut self, target: usize, state: usize) -> Result<(), PickleError> {
        let dtype_kind = match &self.arena[target] {
            Obj::Dtype(None, Some(kind)) => Some(*kind),
            Obj::EmptyArray => None,
            _ => return Err(self.bad("BUILD on an object that is not a numpy dtype or array")),
        };
        match dtype_kind {
            Some(kind) => {
                let items = self
                    .tuple_of(state)
                    .ok_or_else(|| self.bad("a dtype's state is not a tuple"))?;
                let order = items
                    .get(1)
                    .and_then(|&i| self.str_of(i))
                    .ok_or_else(|| self.bad("a dtype's state has no byte order"))?;
                let big_endian = match order {
                    "<" | "|" | "=" => false,
                    ">" => true,
                    other => return Err(self.bad(format!("dtype byte order '{other}'"))),
                };
                self.arena[target] = Obj::Dtype(Some(Dtype { kind, big_endian }), Some(kind));
                Ok(())
            }
            None => {
                let items = self
                    .tuple_of(state)
                    .ok_or_else(|| self.bad("an array's state is not a tuple"))?
                    .to_vec();
                let [_version, shape, dtype, fortran, data] = items[..] else {
                    return Err(self
                        .bad("an array's state is not (version, shape, dtype, is_fortran, data)"));
                };
                let shape = self.shape_of(shape)?;
                let dtype = self.dtype_of(dtype)?;
                let fortran = match self.arena[fortran] {
                    Obj::Bool(b) => b,
                    Obj::Int(i) => i != 0,
                    _ => return Err(self.bad("an array's is_fortran is not a bool")),
                };
                let data = self
                    .bytes_of(data)
                    .ok_or_else(|| {
                        self.bad("an array's data is not bytes (object arrays are not read)")
                    })?
                    .to_vec();
                let array = self.array(shape, dtype, fortran, data)?;
                self.arena[target] = Obj::Array(array);
                Ok(())
            }
        }
    }

    fn run(&mut self) -> Result<usize, PickleError> {
        self.op_at = 0;
        if self.u8()? != 0x80 {
            return Err(self.bad(
                "does not start with PROTO (protocol 0 and 1 pickles are not read: re-save with \
                 protocol 2 or higher)",
            ));
        }
        let proto = self.u8()?;
        if !(2..=5).contains(&proto) {
            return Err(self.bad(format!("protocol {proto} (expected 2 to 5)")));
        }
        loop {
            self.op_at = self.pos;
            let op = self.u8()?;
            match op {
                b'.' => {
                    // STOP
                    let top = self.pop()?;
                    if !self.stack.is_empty() || !self.marks.is_empty() {
                        return Err(self.bad("STOP with values left on the stack"));
                    }
                    return Ok(top);
                }
                0x95 => {
                    // FRAME: a hint for buffered readers; the opcodes follow in line.
                    let n = self.len_u64()?;
                    if n > self.input.len() - self.pos {
                        return Err(PickleError::Truncated(self.input.len()));
                    }
                }
                b'(' => self.marks.push(self.stack.len()),
                b'N' => self.push(Obj::None)?,
                0x88 => self.push(Obj::Bool(true))?,
                0x89 => self.push(Obj::Bool(false))?,
                b'K' => {
                    let v = self.u8()?;
                    self.push(Obj::Int(i64::from(v)))?;
                }
                b'M' => {
                    let v = u16::from_le_bytes(self.le::<2>()?);
                    self.push(Obj::Int(i64::from(v)))?;
                }
                b'J' => {
                    let v = i32::from_le_bytes(self.le::<4>()?);
                    self.push(Obj::Int(i64::from(v)))?;
                }
                0x8a => {
                    // LONG1: a little-endian two's complement integer of n bytes.
                    let n = usize::from(self.u8()?);
                    let bytes = self.take(n)?;
                    if n > 8 {
                        return Err(self.bad("an integer longer than 8 bytes"));
                    }
                    let mut buf = if bytes.last().is_some_and(|&b| b & 0x80 != 0) {
                        [0xffu8; 8]
                    } else {
                        [0u8; 8]
                    };
                    buf[..n].copy_from_slice(bytes);
                    self.push(Obj::Int(i64::from_le_bytes(buf)))?;
                }
                b'X' | 0x8c | 0x8d => {
                    // BINUNICODE, SHORT_BINUNICODE, BINUNICODE8
                    let n = match op {
                        b'X' => u32::from_le_bytes(self.le::<4>()?) as usize,
                        0x8c => usize::from(self.u8()?),
                        _ => self.len_u64()?,
                    };
                    let bytes = self.take(n)?;
                    let text = std::str::from_utf8(bytes)
                        .map_err(|_| self.bad("a str is not UTF-8"))?
                        .to_owned();
                    self.push(Obj::Str(text))?;
                }
                b'C' | b'B' | 0x8e | 0x96 => {
                    // SHORT_BINBYTES, BINBYTES, BINBYTES8, BYTEARRAY8
                    let n = match op {
                        b'C' => usize::from(self.u8()?),
                        b'B' => u32::from_le_bytes(self.le::<4>()?) as usize,
                        _ => self.len_u64()?,
                    };
                    let bytes = self.take(n)?.to_vec();
                    self.push(Obj::Bytes(bytes))?;
                }
                0x97 | 0x98 => {
                    return Err(self.bad(
                        "an out-of-band buffer (NEXT_BUFFER): the pickle does not hold its data \
                         (re-save without buffer_callback)",
                    ))
                }
                b')' => self.push(Obj::Tuple(Vec::new()))?,
                b't' => {
                    let items = self.pop_mark()?;
                    self.push(Obj::Tuple(items))?;
                }
                0x85..=0x87 => {
                    let items = self.pop_n(usize::from(op - 0x84))?;
                    self.push(Obj::Tuple(items))?;
                }
                b']' => self.push(Obj::List(Vec::new()))?,
                b'}' => self.push(Obj::Dict(Vec::new()))?,
                b'l' => {
                    let items = self.pop_mark()?;
                    self.push(Obj::List(items))?;
                }
                b'd' => {
                    let items = self.pop_mark()?;
                    let pairs = self.pairs(items)?;
                    self.push(Obj::Dict(pairs))?;
                }
                b'a' | b'e' => {
                    let items = if op == b'a' {
                        vec![self.pop()?]
                    } else {
                        self.pop_mark()?
                    };
                    let list = self.top()?;
                    match &mut self.arena[list] {
                        Obj::List(l) => l.extend(items),
                        _ => return Err(self.bad("APPEND to something that is not a list")),
                    }
                }
                b's' | b'u' => {
                    let items = if op == b's' {
                        self.pop_n(2)?
                    } else {
                        self.pop_mark()?
                    };
                    let pairs = self.pairs(items)?;
                    let dict = self.top()?;
                    match &mut self.arena[dict] {
                        Obj::Dict(d) => d.extend(pairs),
                        _ => return Err(self.bad("SETITEM on something that is not a dict")),
                    }
                }
                b'c' => {
                    let module = self.line()?;
                    let name = self.line()?;
                    let global = lookup_global(module, name)?;
                    self.push(Obj::Global(global))?;
                }
                0x93 => {
                    // STACK_GLOBAL
                    let name = self.pop()?;
                    let module = self.pop()?;
                    let (Some(module), Some(name)) = (self.str_of(module), self.str_of(name))
                    else {
                        return Err(self.bad("STACK_GLOBAL of values that are not str"));
                    };
                    let global = lookup_global(module, name)?;
                    self.push(Obj::Global(global))?;
                }
                b'R' => {
                    let args = self.pop()?;
                    let callable = self.pop()?;
                    let obj = self.reduce(callable, args)?;
                    self.push(obj)?;
                }
                b'b' => {
                    let state = self.pop()?;
                    let target = self.top()?;
                    self.build(target, state)?;
                }
                b'q' => {
                    let key = self.u8()?;
                    self.memo_put(u32::from(key))?;
                }
                b'r' => {
                    let key = u32::from_le_bytes(self.le::<4>()?);
                    self.memo_put(key)?;
                }
                0x94 => {
                    let key = u32::try_from(self.memo.len())
                        .map_err(|_| self.bad("too many memo entries"))?;
                    self.memo_put(key)?;
                }
                b'h' => {
                    let key = self.u8()?;
                    self.memo_get(u32::from(key))?;
                }
                b'j' => {
                    let key = u32::from_le_bytes(self.le::<4>()?);
                    self.memo_get(key)?;
                }
                0x30 => {
                    // POP
                    self.pop()?;
                }
                other => {
                    return Err(PickleError::Opcode {
                        opcode: other,
                        offset: self.op_at,
                    })
                }
            }
        }
    }

    fn pairs(&self, items: Vec<usize>) -> Result<Vec<(usize, usize)>, PickleError> {
        if items.len() % 2 != 0 {
            return Err(self.bad("a dict with an odd number of keys and values"));
        }
        Ok(items.chunks_exact(2).map(|kv| (kv[0], kv[1])).collect())
    }
}

/// Reads `{"uids": [str], "text_features": N×D float16/float32}` from the bytes of a pickle
/// (protocols 2–5, numpy 1.x and 2.x). Other keys are ignored; the features come back in C
/// order, little-endian, bit for bit as numpy held them.
pub fn read_text_features(input: &[u8]) -> Result<TextFeatures, PickleError> {
    let mut machine = Machine {
        input,
        pos: 0,
        arena: Vec::new(),
        stack: Vec::new(),
        marks: Vec::new(),
        memo: HashMap::new(),
        op_at: 0,
    };
    let root = machine.run()?;
    let content = |m: &str| PickleError::Content(m.to_owned());
    let Obj::Dict(pairs) = &machine.arena[root] else {
        return Err(content(
            "is not a dict (expected {\"uids\": [...], \"text_features\": array})",
        ));
    };
    let field = |key: &str| {
        pairs
            .iter()
            .rev()
            .find(|(k, _)| machine.str_of(*k) == Some(key))
            .map(|(_, v)| *v)
    };
    let uids_id = field("uids").ok_or_else(|| content("has no \"uids\" key"))?;
    let features_id =
        field("text_features").ok_or_else(|| content("has no \"text_features\" key"))?;
    let uids = match &machine.arena[uids_id] {
        Obj::List(items) | Obj::Tuple(items) => items
            .iter()
            .map(|&i| machine.str_of(i).map(str::to_owned))
            .collect::<Option<Vec<String>>>()
            .ok_or_else(|| content("\"uids\" holds something other than str"))?,
        _ => return Err(content("\"uids\" is not a list")),
    };
    let Obj::Array(array) = &machine.arena[features_id] else {
        return Err(content("\"text_features\" is not a numpy array"));
    };
    let (rows, cols) = match array.shape[..] {
        [rows, cols] => (rows, cols),
        [cols] if uids.len() == 1 => (1, cols),
        _ => {
            return Err(content(&format!(
                "\"text_features\" has shape {:?} (expected (N, D), N = {} uids)",
                array.shape,
                uids.len()
            )))
        }
    };
    if rows != uids.len() {
        return Err(content(&format!(
            "\"text_features\" has {rows} rows for {} uids",
            uids.len()
        )));
    }
    let width = array.dtype.kind.width();
    let mut data_le = if array.fortran && rows > 1 && cols > 1 {
        // Column-major to row-major.
        let mut out = vec![0u8; array.data.len()];
        for r in 0..rows {
            for c in 0..cols {
                let from = (c * rows + r) * width;
                let to = (r * cols + c) * width;
                out[to..to + width].copy_from_slice(&array.data[from..from + width]);
            }
        }
        out
    } else {
        array.data.clone()
    };
    if array.dtype.big_endian {
        for element in data_le.chunks_exact_mut(width) {
            element.reverse();
        }
    }
    Ok(TextFeatures {
        uids,
        kind: array.dtype.kind,
        cols,
        data_le,
    })
}

fn put_str(out: &mut Vec<u8>, s: &str) {
    if s.len() < 256 {
        out.push(0x8c);
        out.push(s.len() as u8);
    } else {
        out.push(b'X');
        out.extend_from_slice(&(s.len() as u32).to_le_bytes());
    }
    out.extend_from_slice(s.as_bytes());
}

fn put_int(out: &mut Vec<u8>, v: usize) {
    if let Ok(b) = u8::try_from(v) {
        out.push(b'K');
        out.push(b);
    } else if let Ok(w) = u16::try_from(v) {
        out.push(b'M');
        out.extend_from_slice(&w.to_le_bytes());
    } else if let Ok(i) = i32::try_from(v) {
        out.push(b'J');
        out.extend_from_slice(&i.to_le_bytes());
    } else {
        // LONG1 of 8 bytes: a shape dimension is far below 2^63, so the sign bit is clear.
        out.push(0x8a);
        out.push(8);
        out.extend_from_slice(&(v as u64).to_le_bytes());
    }
}

/// `features` as a protocol-4 pickle of `{"uids": [...], "text_features": array}`, the form
/// MesaTask's `compress_pickle.load` reads: the array through
/// `numpy.core.multiarray._reconstruct` (numpy 2.x maps that name to `numpy._core`), no memo,
/// no frames (both optional in protocol 4). Deterministic: same features, same bytes.
pub fn write_text_features(features: &TextFeatures) -> Vec<u8> {
    let mut out = Vec::with_capacity(features.data_le.len() + 64 * features.uids.len() + 256);
    out.extend_from_slice(&[0x80, 4]);
    out.push(b'}');
    out.push(b'(');
    put_str(&mut out, "uids");
    out.push(b']');
    for chunk in features.uids.chunks(1000) {
        out.push(b'(');
        for uid in chunk {
            put_str(&mut out, uid);
        }
        out.push(b'e');
    }
    put_str(&mut out, "text_features");
    let global = |out: &mut Vec<u8>, module: &str, name: &str| {
        put_str(out, module);
        put_str(out, name);
        out.push(0x93);
    };
    global(&mut out, "numpy.core.multiarray", "_reconstruct");
    global(&mut out, "numpy", "ndarray");
    put_int(&mut out, 0);
    out.push(0x85);
    out.push(b'C');
    out.push(1);
    out.push(b'b');
    out.push(0x87);
    out.push(b'R');
    // state: (1, (rows, cols), dtype, False, data)
    out.push(b'(');
    put_int(&mut out, 1);
    put_int(&mut out, features.uids.len());
    put_int(&mut out, features.cols);
    out.push(0x86);
    global(&mut out, "numpy", "dtype");
    put_str(&mut out, features.kind.numpy());
    out.push(0x89);
    out.push(0x88);
    out.push(0x87);
    out.push(b'R');
    out.push(b'(');
    put_int(&mut out, 3);
    put_str(&mut out, "<");
    out.extend_from_slice(b"NNN");
    out.push(b'J');
    out.extend_from_slice(&(-1i32).to_le_bytes());
    out.push(b'J');
    out.extend_from_slice(&(-1i32).to_le_bytes());
    put_int(&mut out, 0);
    out.push(b't');
    out.push(b'b');
    out.push(0x89);
    out.push(0x8e);
    out.extend_from_slice(&(features.data_le.len() as u64).to_le_bytes());
    out.extend_from_slice(&features.data_le);
    out.push(b't');
    out.push(b'b');
    out.push(b'u');
    out.push(b'.');
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> TextFeatures {
        TextFeatures {
            uids: vec!["a".into(), "b".into()],
            kind: FloatKind::F32,
            cols: 3,
            data_le: (0..6u32)
                .flat_map(|i| (i as f32 * 0.5).to_le_bytes())
                .collect(),
        }
    }

    #[test]
    fn write_then_read_is_the_identity() {
        let features = sample();
        let bytes = write_text_features(&features);
        assert_eq!(read_text_features(&bytes), Ok(features));
    }

    #[test]
    fn wide_rows_and_many_uids_round_trip() {
        // 768 columns and 300 rows need 2-byte integers (BININT2) in the shape.
        let uids: Vec<String> = (0..300).map(|i| format!("uid{i}")).collect();
        let features = TextFeatures {
            data_le: vec![7u8; 300 * 768 * 2],
            uids,
            kind: FloatKind::F16,
            cols: 768,
        };
        let bytes = write_text_features(&features);
        assert_eq!(read_text_features(&bytes), Ok(features));
    }

    #[test]
    fn every_truncation_is_an_error() {
        let bytes = write_text_features(&sample());
        for n in 0..bytes.len() {
            assert!(
                read_text_features(&bytes[..n]).is_err(),
                "prefix of {n} bytes"
            );
        }
        // Control: the whole file reads.
        assert!(read_text_features(&bytes).is_ok());
    }

    #[test]
    fn other_globals_are_refused_by_name() {
        // protocol 2: GLOBAL 'os system', then a call of it.
        let evil = b"\x80\x02cos\nsystem\nX\x02\x00\x00\x00lsq\x00\x85R.";
        let err = read_text_features(evil).expect_err("refused");
        assert_eq!(err, PickleError::Global("os.system".into()));
        assert!(err.to_string().contains("os.system"));
        let evil4 = b"\x80\x04\x8c\x08builtins\x8c\x04eval\x93\x8c\x011\x85R.";
        assert_eq!(
            read_text_features(evil4).expect_err("refused"),
            PickleError::Global("builtins.eval".into())
        );
    }

    #[test]
    fn out_of_band_buffers_are_refused() {
        let bytes = b"\x80\x05\x97.";
        assert!(read_text_features(bytes)
            .expect_err("refused")
            .to_string()
            .contains("out-of-band"));
    }

    #[test]
    fn npy_written_reads_back() {
        let features = sample();
        let npy = features.to_npy();
        assert_eq!(
            TextFeatures::from_npy(&npy, features.uids.clone()),
            Ok(features.clone())
        );
        assert!(TextFeatures::from_npy(&npy[..npy.len() - 1], features.uids.clone()).is_err());
        assert!(TextFeatures::from_npy(&npy, vec!["a".into()]).is_err());
    }

    #[test]
    fn npy_header_is_padded_to_64_bytes() {
        let npy = sample().to_npy();
        let header_len = u16::from_le_bytes([npy[8], npy[9]]) as usize;
        assert_eq!((10 + header_len) % 64, 0);
        assert_eq!(npy.len() - 10 - header_len, 24);
    }
}
