//! Sorted-key JSON written straight from a [`Serialize`] value, byte for byte what
//! `serde_json::to_value` followed by `serde_json::to_vec_pretty` (or `to_string`) writes.
//!
//! Every artifact mesa writes has sorted keys (struct fields too), so that the same value always
//! gives the same bytes. serde_json sorts only through its `Value` tree: a `BTreeMap` with a
//! `String` per key and per string, and a node per value, built and dropped for every file. That
//! round trip was a sixth of a cheap stage's time (`mesa graph`: building `graph.json`'s `Value`
//! cost more than extracting the graph). No crate writes sorted JSON from `Serialize` directly,
//! so this one does, in one buffer:
//!
//! - arrays stream as they come;
//! - an object's members are written, each at its own depth, into the buffer as they come, with
//!   their keys noted; at the object's end the members are laid out again in key order (`Value`'s
//!   order: bytewise on the key text; of two members with one key, the later one, as a map insert
//!   keeps it) and moved back over the unsorted text;
//! - leaves go through serde_json's own writer, so strings are escaped and numbers spelled as
//!   serde_json spells them; an `f32` is widened to `f64` first, as `Value` stores it; a
//!   non-finite float is `null`, as in `Value`.
//!
//! `schemas/tests/sorted_writer.rs` compares it with the `Value` path on every shape of serde's
//! data model and on random documents, `pipeline/tests/artifact_bytes.rs` on every artifact of a
//! demo `mesa run` read back into its type.

use std::borrow::Cow;

use serde::ser::{self, Impossible, Serialize};

type Error = serde_json::Error;

fn error(message: &str) -> Error {
    <Error as ser::Error>::custom(message)
}

/// Writes `value` with sorted keys: two-space indentation when `pretty`, else on one line.
pub fn write_sorted<T: Serialize + ?Sized>(value: &T, pretty: bool) -> Result<Vec<u8>, Error> {
    let mut writer = Writer {
        out: Vec::with_capacity(4096),
        depth: 0,
        pretty,
        pool: Vec::new(),
    };
    value.serialize(&mut writer)?;
    Ok(writer.out)
}

/// One member of an object being written: its key and where its value's text is in the buffer.
struct Member {
    key: Cow<'static, str>,
    start: usize,
    end: usize,
}

struct Writer {
    out: Vec<u8>,
    /// Nesting depth of the value being written (its members are indented one more).
    depth: usize,
    pretty: bool,
    /// Member lists of finished objects, kept for the next ones.
    pool: Vec<Vec<Member>>,
}

impl Writer {
    fn newline_indent(&mut self, depth: usize) {
        if self.pretty {
            self.out.push(b'\n');
            self.out.resize(self.out.len() + 2 * depth, b' ');
        }
    }

    fn leaf<T: Serialize + ?Sized>(&mut self, value: &T) -> Result<(), Error> {
        serde_json::to_writer(&mut self.out, value)
    }

    fn float(&mut self, value: f64) -> Result<(), Error> {
        if value.is_finite() {
            self.leaf(&value)
        } else {
            self.out.extend_from_slice(b"null");
            Ok(())
        }
    }

    fn begin_object(&mut self) -> Object<'_> {
        let members = self.pool.pop().unwrap_or_default();
        let start = self.out.len();
        self.depth += 1;
        Object {
            writer: self,
            start,
            members,
            key: None,
        }
    }

    fn begin_array(&mut self) -> Array<'_> {
        self.out.push(b'[');
        self.depth += 1;
        Array {
            writer: self,
            first: true,
        }
    }
}

/// An array being written: elements stream into the buffer.
struct Array<'w> {
    writer: &'w mut Writer,
    first: bool,
}

impl Array<'_> {
    fn element<T: Serialize + ?Sized>(&mut self, value: &T) -> Result<(), Error> {
        if !self.first {
            self.writer.out.push(b',');
        }
        self.first = false;
        let depth = self.writer.depth;
        self.writer.newline_indent(depth);
        value.serialize(&mut *self.writer)
    }

    fn finish(self) {
        self.writer.depth -= 1;
        if !self.first {
            let depth = self.writer.depth;
            self.writer.newline_indent(depth);
        }
        self.writer.out.push(b']');
    }
}

/// An object being written: members go into the buffer unsorted, and are laid out in key order
/// at the end.
struct Object<'w> {
    writer: &'w mut Writer,
    /// Where the object's text starts.
    start: usize,
    members: Vec<Member>,
    /// A map's key, between `serialize_key` and `serialize_value`.
    key: Option<String>,
}

impl<'w> Object<'w> {
    fn member<T: Serialize + ?Sized>(
        &mut self,
        key: Cow<'static, str>,
        value: &T,
    ) -> Result<(), Error> {
        let start = self.writer.out.len();
        value.serialize(&mut *self.writer)?;
        let end = self.writer.out.len();
        self.members.push(Member { key, start, end });
        Ok(())
    }

    /// Lays the members out in key order; gives the writer back (a struct variant's outer
    /// object goes on with it).
    fn finish(mut self) -> Result<&'w mut Writer, Error> {
        let writer = &mut *self.writer;
        writer.depth -= 1;
        let depth = writer.depth;
        let members = &mut self.members;
        // Key order, and of equal keys the last written: the stable sort keeps them in writing
        // order, and each replaces the one before it.
        members.sort_by(|a, b| a.key.as_bytes().cmp(b.key.as_bytes()));
        if members.windows(2).any(|w| w[0].key == w[1].key) {
            let mut kept: Vec<Member> = Vec::with_capacity(members.len());
            for member in members.drain(..) {
                match kept.last_mut() {
                    Some(last) if last.key == member.key => *last = member,
                    _ => kept.push(member),
                }
            }
            *members = kept;
        }
        let unsorted_end = writer.out.len();
        writer.out.push(b'{');
        for (i, member) in members.iter().enumerate() {
            if i > 0 {
                writer.out.push(b',');
            }
            writer.newline_indent(depth + 1);
            serde_json::to_writer(&mut writer.out, member.key.as_ref())?;
            writer
                .out
                .extend_from_slice(if writer.pretty { b": " } else { b":" });
            writer.out.extend_from_within(member.start..member.end);
        }
        if !members.is_empty() {
            writer.newline_indent(depth);
        }
        writer.out.push(b'}');
        // The sorted text replaces the unsorted one.
        writer.out.copy_within(unsorted_end.., self.start);
        let len = writer.out.len() - unsorted_end;
        writer.out.truncate(self.start + len);
        members.clear();
        writer.pool.push(std::mem::take(members));
        Ok(self.writer)
    }
}

impl<'w> ser::Serializer for &'w mut Writer {
    type Ok = ();
    type Error = Error;
    type SerializeSeq = Array<'w>;
    type SerializeTuple = Array<'w>;
    type SerializeTupleStruct = Array<'w>;
    type SerializeTupleVariant = TupleVariant<'w>;
    type SerializeMap = Object<'w>;
    type SerializeStruct = Object<'w>;
    type SerializeStructVariant = StructVariant<'w>;

    fn serialize_bool(self, v: bool) -> Result<(), Error> {
        self.leaf(&v)
    }
    fn serialize_i8(self, v: i8) -> Result<(), Error> {
        self.leaf(&v)
    }
    fn serialize_i16(self, v: i16) -> Result<(), Error> {
        self.leaf(&v)
    }
    fn serialize_i32(self, v: i32) -> Result<(), Error> {
        self.leaf(&v)
    }
    fn serialize_i64(self, v: i64) -> Result<(), Error> {
        self.leaf(&v)
    }
    fn serialize_i128(self, v: i128) -> Result<(), Error> {
        // As `Value` holds it: a 64-bit integer, or an error.
        match (u64::try_from(v), i64::try_from(v)) {
            (Ok(u), _) => self.leaf(&u),
            (_, Ok(i)) => self.leaf(&i),
            _ => Err(error("number out of range")),
        }
    }
    fn serialize_u8(self, v: u8) -> Result<(), Error> {
        self.leaf(&v)
    }
    fn serialize_u16(self, v: u16) -> Result<(), Error> {
        self.leaf(&v)
    }
    fn serialize_u32(self, v: u32) -> Result<(), Error> {
        self.leaf(&v)
    }
    fn serialize_u64(self, v: u64) -> Result<(), Error> {
        self.leaf(&v)
    }
    fn serialize_u128(self, v: u128) -> Result<(), Error> {
        match u64::try_from(v) {
            Ok(u) => self.leaf(&u),
            Err(_) => Err(error("number out of range")),
        }
    }
    fn serialize_f32(self, v: f32) -> Result<(), Error> {
        // `Value` widens an f32 to f64.
        self.float(f64::from(v))
    }
    fn serialize_f64(self, v: f64) -> Result<(), Error> {
        self.float(v)
    }
    fn serialize_char(self, v: char) -> Result<(), Error> {
        self.leaf(&v)
    }
    fn serialize_str(self, v: &str) -> Result<(), Error> {
        self.leaf(v)
    }
    fn serialize_bytes(self, v: &[u8]) -> Result<(), Error> {
        let mut array = self.begin_array();
        for byte in v {
            array.element(byte)?;
        }
        array.finish();
        Ok(())
    }
    fn serialize_none(self) -> Result<(), Error> {
        self.serialize_unit()
    }
    fn serialize_some<T: Serialize + ?Sized>(self, value: &T) -> Result<(), Error> {
        value.serialize(self)
    }
    fn serialize_unit(self) -> Result<(), Error> {
        self.out.extend_from_slice(b"null");
        Ok(())
    }
    fn serialize_unit_struct(self, _name: &'static str) -> Result<(), Error> {
        self.serialize_unit()
    }
    fn serialize_unit_variant(
        self,
        _name: &'static str,
        _index: u32,
        variant: &'static str,
    ) -> Result<(), Error> {
        self.leaf(variant)
    }
    fn serialize_newtype_struct<T: Serialize + ?Sized>(
        self,
        _name: &'static str,
        value: &T,
    ) -> Result<(), Error> {
        value.serialize(self)
    }
    fn serialize_newtype_variant<T: Serialize + ?Sized>(
        self,
        _name: &'static str,
        _index: u32,
        variant: &'static str,
        value: &T,
    ) -> Result<(), Error> {
        let mut object = self.begin_object();
        object.member(Cow::Borrowed(variant), value)?;
        object.finish().map(drop)
    }
    fn serialize_seq(self, _len: Option<usize>) -> Result<Array<'w>, Error> {
        Ok(self.begin_array())
    }
    fn serialize_tuple(self, _len: usize) -> Result<Array<'w>, Error> {
        Ok(self.begin_array())
    }
    fn serialize_tuple_struct(self, _name: &'static str, _len: usize) -> Result<Array<'w>, Error> {
        Ok(self.begin_array())
    }
    fn serialize_tuple_variant(
        self,
        _name: &'static str,
        _index: u32,
        variant: &'static str,
        _len: usize,
    ) -> Result<TupleVariant<'w>, Error> {
        // `{"variant": [...]}`: the array is the object's one member.
        let object = self.begin_object();
        let start = object.writer.out.len();
        object.writer.out.push(b'[');
        object.writer.depth += 1;
        Ok(TupleVariant {
            object,
            variant,
            start,
            first: true,
        })
    }
    fn serialize_map(self, _len: Option<usize>) -> Result<Object<'w>, Error> {
        Ok(self.begin_object())
    }
    fn serialize_struct(self, name: &'static str, _len: usize) -> Result<Object<'w>, Error> {
        if name.starts_with("$serde_json::private::") {
            // serde_json's raw values and arbitrary-precision numbers are structs with these
            // names that `Value` treats specially; no mesa artifact holds one.
            return Err(error(
                "sorted JSON writer: serde_json's private value types are not supported",
            ));
        }
        Ok(self.begin_object())
    }
    fn serialize_struct_variant(
        self,
        _name: &'static str,
        _index: u32,
        variant: &'static str,
        _len: usize,
    ) -> Result<StructVariant<'w>, Error> {
        // `{"variant": {...}}`: the inner object is the outer one's one member; both open here.
        let outer = self.begin_object();
        let (writer, outer_start, outer_members) = (outer.writer, outer.start, outer.members);
        Ok(StructVariant {
            inner: writer.begin_object(),
            outer_start,
            outer_members,
            variant,
        })
    }
}

/// `{"variant": [fields]}`.
struct TupleVariant<'w> {
    object: Object<'w>,
    variant: &'static str,
    /// Where the array's text starts.
    start: usize,
    first: bool,
}

/// `{"variant": {fields}}`: the outer object's state is kept apart while the inner one holds
/// the writer.
struct StructVariant<'w> {
    inner: Object<'w>,
    outer_start: usize,
    outer_members: Vec<Member>,
    variant: &'static str,
}

/// A sequence, a tuple and a tuple struct are all arrays.
macro_rules! array_like {
    ($($trait:ident :: $element:ident),*) => {$(
        impl ser::$trait for Array<'_> {
            type Ok = ();
            type Error = Error;
            fn $element<T: Serialize + ?Sized>(&mut self, value: &T) -> Result<(), Error> {
                self.element(value)
            }
            fn end(self) -> Result<(), Error> {
                self.finish();
                Ok(())
            }
        }
    )*};
}

array_like!(
    SerializeSeq::serialize_element,
    SerializeTuple::serialize_element,
    SerializeTupleStruct::serialize_field
);

impl ser::SerializeTupleVariant for TupleVariant<'_> {
    type Ok = ();
    type Error = Error;
    fn serialize_field<T: Serialize + ?Sized>(&mut self, value: &T) -> Result<(), Error> {
        let mut array = Array {
            writer: &mut *self.object.writer,
            first: self.first,
        };
        array.element(value)?;
        self.first = false;
        Ok(())
    }
    fn end(mut self) -> Result<(), Error> {
        Array {
            writer: &mut *self.object.writer,
            first: self.first,
        }
        .finish();
        let end = self.object.writer.out.len();
        self.object.members.push(Member {
            key: Cow::Borrowed(self.variant),
            start: self.start,
            end,
        });
        self.object.finish().map(drop)
    }
}

impl ser::SerializeMap for Object<'_> {
    type Ok = ();
    type Error = Error;
    fn serialize_key<T: Serialize + ?Sized>(&mut self, key: &T) -> Result<(), Error> {
        self.key = Some(key.serialize(KeyWriter)?);
        Ok(())
    }
    fn serialize_value<T: Serialize + ?Sized>(&mut self, value: &T) -> Result<(), Error> {
        let key = self
            .key
            .take()
            .ok_or_else(|| error("serialize_value called before serialize_key"))?;
        self.member(Cow::Owned(key), value)
    }
    fn end(self) -> Result<(), Error> {
        self.finish().map(drop)
    }
}

impl ser::SerializeStruct for Object<'_> {
    type Ok = ();
    type Error = Error;
    fn serialize_field<T: Serialize + ?Sized>(
        &mut self,
        key: &'static str,
        value: &T,
    ) -> Result<(), Error> {
        self.member(Cow::Borrowed(key), value)
    }
    fn end(self) -> Result<(), Error> {
        self.finish().map(drop)
    }
}

impl ser::SerializeStructVariant for StructVariant<'_> {
    type Ok = ();
    type Error = Error;
    fn serialize_field<T: Serialize + ?Sized>(
        &mut self,
        key: &'static str,
        value: &T,
    ) -> Result<(), Error> {
        self.inner.member(Cow::Borrowed(key), value)
    }
    fn end(self) -> Result<(), Error> {
        let start = self.inner.start;
        let writer = self.inner.finish()?;
        let end = writer.out.len();
        let mut members = self.outer_members;
        members.push(Member {
            key: Cow::Borrowed(self.variant),
            start,
            end,
        });
        Object {
            writer,
            start: self.outer_start,
            members,
            key: None,
        }
        .finish()
        .map(drop)
    }
}

/// A map key as `Value`'s map writes it (serde_json's `MapKeySerializer`): strings, and
/// numbers, booleans and unit variants as their text.
struct KeyWriter;

fn key_must_be_a_string() -> Error {
    error("key must be a string")
}

impl ser::Serializer for KeyWriter {
    type Ok = String;
    type Error = Error;
    type SerializeSeq = Impossible<String, Error>;
    type SerializeTuple = Impossible<String, Error>;
    type SerializeTupleStruct = Impossible<String, Error>;
    type SerializeTupleVariant = Impossible<String, Error>;
    type SerializeMap = Impossible<String, Error>;
    type SerializeStruct = Impossible<String, Error>;
    type SerializeStructVariant = Impossible<String, Error>;

    fn serialize_bool(self, v: bool) -> Result<String, Error> {
        Ok(v.to_string())
    }
    fn serialize_i8(self, v: i8) -> Result<String, Error> {
        Ok(v.to_string())
    }
    fn serialize_i16(self, v: i16) -> Result<String, Error> {
        Ok(v.to_string())
    }
    fn serialize_i32(self, v: i32) -> Result<String, Error> {
        Ok(v.to_string())
    }
    fn serialize_i64(self, v: i64) -> Result<String, Error> {
        Ok(v.to_string())
    }
    fn serialize_i128(self, v: i128) -> Result<String, Error> {
        Ok(v.to_string())
    }
    fn serialize_u8(self, v: u8) -> Result<String, Error> {
        Ok(v.to_string())
    }
    fn serialize_u16(self, v: u16) -> Result<String, Error> {
        Ok(v.to_string())
    }
    fn serialize_u32(self, v: u32) -> Result<String, Error> {
        Ok(v.to_string())
    }
    fn serialize_u64(self, v: u64) -> Result<String, Error> {
        Ok(v.to_string())
    }
    fn serialize_u128(self, v: u128) -> Result<String, Error> {
        Ok(v.to_string())
    }
    fn serialize_f32(self, v: f32) -> Result<String, Error> {
        // serde_json writes a finite f32 key in its own shortest form (not widened).
        if v.is_finite() {
            serde_json::to_string(&v)
        } else {
            Err(error("float key must be finite (got NaN or +/-inf)"))
        }
    }
    fn serialize_f64(self, v: f64) -> Result<String, Error> {
        if v.is_finite() {
            serde_json::to_string(&v)
        } else {
            Err(error("float key must be finite (got NaN or +/-inf)"))
        }
    }
    fn serialize_char(self, v: char) -> Result<String, Error> {
        Ok(v.to_string())
    }
    fn serialize_str(self, v: &str) -> Result<String, Error> {
        Ok(v.to_owned())
    }
    fn serialize_bytes(self, _v: &[u8]) -> Result<String, Error> {
        Err(key_must_be_a_string())
    }
    fn serialize_none(self) -> Result<String, Error> {
        Err(key_must_be_a_string())
    }
    fn serialize_some<T: Serialize + ?Sized>(self, _value: &T) -> Result<String, Error> {
        Err(key_must_be_a_string())
    }
    fn serialize_unit(self) -> Result<String, Error> {
        Err(key_must_be_a_string())
    }
    fn serialize_unit_struct(self, _name: &'static str) -> Result<String, Error> {
        Err(key_must_be_a_string())
    }
    fn serialize_unit_variant(
        self,
        _name: &'static str,
        _index: u32,
        variant: &'static str,
    ) -> Result<String, Error> {
        Ok(variant.to_owned())
    }
    fn serialize_newtype_struct<T: Serialize + ?Sized>(
        self,
        _name: &'static str,
        value: &T,
    ) -> Result<String, Error> {
        value.serialize(self)
    }
    fn serialize_newtype_variant<T: Serialize + ?Sized>(
        self,
        _name: &'static str,
        _index: u32,
        _variant: &'static str,
        _value: &T,
    ) -> Result<String, Error> {
        Err(key_must_be_a_string())
    }
    fn serialize_seq(self, _len: Option<usize>) -> Result<Self::SerializeSeq, Error> {
        Err(key_must_be_a_string())
    }
    fn serialize_tuple(self, _len: usize) -> Result<Self::SerializeTuple, Error> {
        Err(key_must_be_a_string())
    }
    fn serialize_tuple_struct(
        self,
        _name: &'static str,
        _len: usize,
    ) -> Result<Self::SerializeTupleStruct, Error> {
        Err(key_must_be_a_string())
    }
    fn serialize_tuple_variant(
        self,
        _name: &'static str,
        _index: u32,
        _variant: &'static str,
        _len: usize,
    ) -> Result<Self::SerializeTupleVariant, Error> {
        Err(key_must_be_a_string())
    }
    fn serialize_map(self, _len: Option<usize>) -> Result<Self::SerializeMap, Error> {
        Err(key_must_be_a_string())
    }
    fn serialize_struct(
        self,
        _name: &'static str,
        _len: usize,
    ) -> Result<Self::SerializeStruct, Error> {
        Err(key_must_be_a_string())
    }
    fn serialize_struct_variant(
        self,
        _name: &'static str,
        _index: u32,
        _variant: &'static str,
        _len: usize,
    ) -> Result<Self::SerializeStructVariant, Error> {
        Err(key_must_be_a_string())
    }
}
