//! The layout tables of `LAYOUT.md`, generated from the types themselves.
//!
//! A recording `serde::Serializer` walks the examples of every variant and notes each
//! type's fields (names, wire types) and each enum's variants (names, tags), exactly as
//! postcard would write them. The tables rendered from that record are what `LAYOUT.md`
//! holds between its markers, so the document cannot go stale: the test fails until
//! `UPDATE_GOLDEN=1` rewrites it.

use std::collections::BTreeMap;
use std::fmt::{self, Write as _};

use serde::Serialize;
use serde::ser::{self, Impossible};

/// The wire shape of one value.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum Shape {
    /// A primitive: `bool`, `u8`, `u16`, `u32`, `u64`, `i32`, `f32`, ...
    Prim(&'static str),
    /// A UTF-8 string with a varint length.
    Str,
    /// A variable-length sequence with a varint length.
    Seq(Box<Shape>),
    /// A fixed-length array (or tuple of one type): no length on the wire.
    Array(usize, Box<Shape>),
    /// A tuple of different types.
    Tuple(Vec<Shape>),
    /// An `Option`: tag 0 (none) or 1 then the value.
    Option(Box<Shape>),
    /// `()`: nothing.
    Unit,
    /// A named struct or enum (its own table).
    Named(&'static str),
}

/// The fields of a struct or enum variant.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum Fields {
    Unit,
    Newtype(Shape),
    Tuple(Vec<Shape>),
    Named(Vec<(&'static str, Shape)>),
}

/// A named type.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum Def {
    Struct(Fields),
    /// Variant index -> (name, fields).
    Enum(BTreeMap<u32, (&'static str, Fields)>),
}

/// Every named type seen, in order of first appearance.
#[derive(Debug, Default)]
pub(crate) struct Registry {
    pub order: Vec<&'static str>,
    pub defs: BTreeMap<&'static str, Def>,
}

impl Registry {
    /// Records the shape of `value` (and every type inside it).
    pub fn record<T: Serialize + ?Sized>(&mut self, value: &T) -> Shape {
        value
            .serialize(Recorder { reg: self })
            .unwrap_or_else(|e| panic!("cannot record a layout: {e}"))
    }

    fn reserve(&mut self, name: &'static str) {
        if !self.order.contains(&name) {
            self.order.push(name);
        }
    }

    fn add_struct(&mut self, name: &'static str, fields: Fields) {
        let def = Def::Struct(fields);
        match self.defs.get(name) {
            None => {
                self.defs.insert(name, def);
            }
            Some(old) => assert_eq!(old, &def, "type {name} recorded with two layouts"),
        }
    }

    fn add_variant(
        &mut self,
        name: &'static str,
        index: u32,
        variant: &'static str,
        fields: Fields,
    ) {
        let def = self
            .defs
            .entry(name)
            .or_insert_with(|| Def::Enum(BTreeMap::new()));
        let Def::Enum(variants) = def else {
            panic!("{name} is both a struct and an enum");
        };
        match variants.get(&index) {
            None => {
                variants.insert(index, (variant, fields));
            }
            Some(old) => assert_eq!(
                old,
                &(variant, fields),
                "variant {name}::{variant} recorded with two layouts"
            ),
        }
    }
}

#[derive(Debug)]
pub(crate) struct RecordError(String);

impl fmt::Display for RecordError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for RecordError {}

impl ser::Error for RecordError {
    fn custom<T: fmt::Display>(msg: T) -> Self {
        Self(msg.to_string())
    }
}

type Result<T> = std::result::Result<T, RecordError>;

struct Recorder<'a> {
    reg: &'a mut Registry,
}

impl<'a> ser::Serializer for Recorder<'a> {
    type Ok = Shape;
    type Error = RecordError;
    type SerializeSeq = Collect<'a>;
    type SerializeTuple = Collect<'a>;
    type SerializeTupleStruct = Collect<'a>;
    type SerializeTupleVariant = Collect<'a>;
    type SerializeMap = Impossible<Shape, RecordError>;
    type SerializeStruct = Collect<'a>;
    type SerializeStructVariant = Collect<'a>;

    fn is_human_readable(&self) -> bool {
        false
    }
    fn serialize_bool(self, _: bool) -> Result<Shape> {
        Ok(Shape::Prim("bool"))
    }
    fn serialize_i8(self, _: i8) -> Result<Shape> {
        Ok(Shape::Prim("i8"))
    }
    fn serialize_i16(self, _: i16) -> Result<Shape> {
        Ok(Shape::Prim("i16"))
    }
    fn serialize_i32(self, _: i32) -> Result<Shape> {
        Ok(Shape::Prim("i32"))
    }
    fn serialize_i64(self, _: i64) -> Result<Shape> {
        Ok(Shape::Prim("i64"))
    }
    fn serialize_u8(self, _: u8) -> Result<Shape> {
        Ok(Shape::Prim("u8"))
    }
    fn serialize_u16(self, _: u16) -> Result<Shape> {
        Ok(Shape::Prim("u16"))
    }
    fn serialize_u32(self, _: u32) -> Result<Shape> {
        Ok(Shape::Prim("u32"))
    }
    fn serialize_u64(self, _: u64) -> Result<Shape> {
        Ok(Shape::Prim("u64"))
    }
    fn serialize_f32(self, _: f32) -> Result<Shape> {
        Ok(Shape::Prim("f32"))
    }
    fn serialize_f64(self, _: f64) -> Result<Shape> {
        Ok(Shape::Prim("f64"))
    }
    fn serialize_char(self, _: char) -> Result<Shape> {
        Ok(Shape::Prim("char"))
    }
    fn serialize_str(self, _: &str) -> Result<Shape> {
        Ok(Shape::Str)
    }
    fn collect_str<T: fmt::Display + ?Sized>(self, _: &T) -> Result<Shape> {
        Ok(Shape::Str)
    }
    fn serialize_bytes(self, _: &[u8]) -> Result<Shape> {
        Ok(Shape::Seq(Box::new(Shape::Prim("u8"))))
    }
    fn serialize_none(self) -> Result<Shape> {
        Err(ser::Error::custom(
            "give Option fields a Some in the examples",
        ))
    }
    fn serialize_some<T: Serialize + ?Sized>(self, value: &T) -> Result<Shape> {
        Ok(Shape::Option(Box::new(self.reg.record(value))))
    }
    fn serialize_unit(self) -> Result<Shape> {
        Ok(Shape::Unit)
    }
    fn serialize_unit_struct(self, name: &'static str) -> Result<Shape> {
        self.reg.reserve(name);
        self.reg.add_struct(name, Fields::Unit);
        Ok(Shape::Named(name))
    }
    fn serialize_unit_variant(
        self,
        name: &'static str,
        index: u32,
        variant: &'static str,
    ) -> Result<Shape> {
        self.reg.reserve(name);
        self.reg.add_variant(name, index, variant, Fields::Unit);
        Ok(Shape::Named(name))
    }
    fn serialize_newtype_struct<T: Serialize + ?Sized>(
        self,
        name: &'static str,
        value: &T,
    ) -> Result<Shape> {
        self.reg.reserve(name);
        let inner = self.reg.record(value);
        self.reg.add_struct(name, Fields::Newtype(inner));
        Ok(Shape::Named(name))
    }
    fn serialize_newtype_variant<T: Serialize + ?Sized>(
        self,
        name: &'static str,
        index: u32,
        variant: &'static str,
        value: &T,
    ) -> Result<Shape> {
        self.reg.reserve(name);
        let inner = self.reg.record(value);
        self.reg
            .add_variant(name, index, variant, Fields::Newtype(inner));
        Ok(Shape::Named(name))
    }
    fn serialize_seq(self, _: Option<usize>) -> Result<Collect<'a>> {
        Ok(Collect::new(self.reg, Kind::Seq))
    }
    fn serialize_tuple(self, _: usize) -> Result<Collect<'a>> {
        Ok(Collect::new(self.reg, Kind::Tuple))
    }
    fn serialize_tuple_struct(self, name: &'static str, _: usize) -> Result<Collect<'a>> {
        self.reg.reserve(name);
        Ok(Collect::new(self.reg, Kind::TupleStruct(name)))
    }
    fn serialize_tuple_variant(
        self,
        name: &'static str,
        index: u32,
        variant: &'static str,
        _: usize,
    ) -> Result<Collect<'a>> {
        self.reg.reserve(name);
        Ok(Collect::new(
            self.reg,
            Kind::TupleVariant(name, index, variant),
        ))
    }
    fn serialize_map(self, _: Option<usize>) -> Result<Self::SerializeMap> {
        Err(ser::Error::custom("maps are not part of the wire format"))
    }
    fn serialize_struct(self, name: &'static str, _: usize) -> Result<Collect<'a>> {
        self.reg.reserve(name);
        Ok(Collect::new(self.reg, Kind::Struct(name)))
    }
    fn serialize_struct_variant(
        self,
        name: &'static str,
        index: u32,
        variant: &'static str,
        _: usize,
    ) -> Result<Collect<'a>> {
        self.reg.reserve(name);
        Ok(Collect::new(
            self.reg,
            Kind::StructVariant(name, index, variant),
        ))
    }
}

enum Kind {
    Seq,
    Tuple,
    TupleStruct(&'static str),
    TupleVariant(&'static str, u32, &'static str),
    Struct(&'static str),
    StructVariant(&'static str, u32, &'static str),
}

/// Collects the elements or fields of a compound value.
struct Collect<'a> {
    reg: &'a mut Registry,
    kind: Kind,
    items: Vec<(&'static str, Shape)>,
}

impl<'a> Collect<'a> {
    fn new(reg: &'a mut Registry, kind: Kind) -> Self {
        Self {
            reg,
            kind,
            items: Vec::new(),
        }
    }

    fn push<T: Serialize + ?Sized>(&mut self, key: &'static str, value: &T) -> Result<()> {
        let shape = self.reg.record(value);
        self.items.push((key, shape));
        Ok(())
    }

    fn shapes(&self) -> Vec<Shape> {
        self.items.iter().map(|(_, s)| s.clone()).collect()
    }

    fn finish(self) -> Result<Shape> {
        let shapes = self.shapes();
        Ok(match self.kind {
            Kind::Seq => {
                let first = shapes.first().cloned().ok_or_else(|| {
                    ser::Error::custom("give sequences an element in the examples")
                })?;
                assert!(shapes.iter().all(|s| *s == first), "mixed sequence");
                Shape::Seq(Box::new(first))
            }
            Kind::Tuple => tuple(shapes),
            Kind::TupleStruct(name) => {
                self.reg.add_struct(name, Fields::Tuple(shapes));
                Shape::Named(name)
            }
            Kind::TupleVariant(name, index, variant) => {
                self.reg
                    .add_variant(name, index, variant, Fields::Tuple(shapes));
                Shape::Named(name)
            }
            Kind::Struct(name) => {
                self.reg.add_struct(name, Fields::Named(self.items));
                Shape::Named(name)
            }
            Kind::StructVariant(name, index, variant) => {
                self.reg
                    .add_variant(name, index, variant, Fields::Named(self.items));
                Shape::Named(name)
            }
        })
    }
}

/// A tuple of one repeated type is a fixed array.
fn tuple(shapes: Vec<Shape>) -> Shape {
    match shapes.first() {
        Some(first) if shapes.iter().all(|s| s == first) => {
            Shape::Array(shapes.len(), Box::new(first.clone()))
        }
        _ => Shape::Tuple(shapes),
    }
}

macro_rules! forward_compound {
    ($($trait:ident :: $method:ident),*) => {$(
        impl ser::$trait for Collect<'_> {
            type Ok = Shape;
            type Error = RecordError;
            fn $method<T: Serialize + ?Sized>(&mut self, value: &T) -> Result<()> {
                self.push("", value)
            }
            fn end(self) -> Result<Shape> {
                self.finish()
            }
        }
    )*};
}

forward_compound!(
    SerializeSeq::serialize_element,
    SerializeTuple::serialize_element,
    SerializeTupleStruct::serialize_field,
    SerializeTupleVariant::serialize_field
);

impl ser::SerializeStruct for Collect<'_> {
    type Ok = Shape;
    type Error = RecordError;
    fn serialize_field<T: Serialize + ?Sized>(
        &mut self,
        key: &'static str,
        value: &T,
    ) -> Result<()> {
        self.push(key, value)
    }
    fn end(self) -> Result<Shape> {
        self.finish()
    }
}

impl ser::SerializeStructVariant for Collect<'_> {
    type Ok = Shape;
    type Error = RecordError;
    fn serialize_field<T: Serialize + ?Sized>(
        &mut self,
        key: &'static str,
        value: &T,
    ) -> Result<()> {
        self.push(key, value)
    }
    fn end(self) -> Result<Shape> {
        self.finish()
    }
}

/// What the layout needs beyond the types: string and sequence capacities (by type and
/// field) and the names of flag bits (by flag-set type).
pub(crate) struct Context {
    pub capacities: Vec<(&'static str, &'static str, usize)>,
    pub flags: Vec<(&'static str, &'static str, u64)>,
}

impl Context {
    fn capacity(&self, ty: &str, field: &str) -> usize {
        self.capacities
            .iter()
            .find(|(t, f, _)| *t == ty && *f == field)
            .map(|c| c.2)
            .unwrap_or_else(|| panic!("give {ty}.{field} a capacity in the layout context"))
    }

    fn flag_bits(&self, ty: &str) -> Vec<(&'static str, u64)> {
        self.flags
            .iter()
            .filter(|(t, _, _)| *t == ty)
            .map(|(_, n, b)| (*n, *b))
            .collect()
    }
}

/// Smallest and largest encoded size, bytes.
pub(crate) type Size = (usize, usize);

fn prim_size(p: &str) -> Size {
    match p {
        "bool" | "u8" | "i8" => (1, 1),
        "u16" | "i16" => (1, 3),
        "u32" | "i32" | "char" => (1, 5),
        "u64" | "i64" => (1, 10),
        "f32" => (4, 4),
        "f64" => (8, 8),
        other => panic!("no size for {other}"),
    }
}

fn prim_text(p: &str) -> &'static str {
    match p {
        "bool" => "bool (0 or 1)",
        "u8" => "u8",
        "i8" => "i8",
        "u16" => "u16 varint",
        "u32" => "u32 varint",
        "u64" => "u64 varint",
        "i16" => "i16 zigzag varint",
        "i32" => "i32 zigzag varint",
        "i64" => "i64 zigzag varint",
        "f32" => "f32 LE",
        "f64" => "f64 LE",
        "char" => "char (UTF-8, varint length)",
        other => panic!("no text for {other}"),
    }
}

impl Registry {
    /// Size of a value of `shape`, found in field `field` of type `owner`.
    pub fn size(&self, shape: &Shape, owner: &str, field: &str, cx: &Context) -> Size {
        match shape {
            Shape::Prim(p) => prim_size(p),
            Shape::Str => {
                let cap = cx.capacity(owner, field);
                (1, crate::varint_len(cap as u64) + cap)
            }
            Shape::Seq(elem) => {
                let (_, max) = self.size(elem, owner, field, cx);
                let cap = cx.capacity(owner, field);
                (1, crate::varint_len(cap as u64) + cap * max)
            }
            Shape::Array(n, elem) => {
                let (min, max) = self.size(elem, owner, field, cx);
                (n * min, n * max)
            }
            Shape::Tuple(items) => items.iter().fold((0, 0), |acc, s| {
                let (a, b) = self.size(s, owner, field, cx);
                (acc.0 + a, acc.1 + b)
            }),
            Shape::Option(inner) => (1, 1 + self.size(inner, owner, field, cx).1),
            Shape::Unit => (0, 0),
            Shape::Named(name) => self.type_size(name, cx),
        }
    }

    fn fields_size(&self, fields: &Fields, owner: &str, cx: &Context) -> Size {
        match fields {
            Fields::Unit => (0, 0),
            Fields::Newtype(s) => self.size(s, owner, "", cx),
            Fields::Tuple(items) => items.iter().fold((0, 0), |acc, s| {
                let (a, b) = self.size(s, owner, "", cx);
                (acc.0 + a, acc.1 + b)
            }),
            Fields::Named(items) => items.iter().fold((0, 0), |acc, (f, s)| {
                let (a, b) = self.size(s, owner, f, cx);
                (acc.0 + a, acc.1 + b)
            }),
        }
    }

    /// Smallest and largest encoding of the named type, bytes.
    pub fn type_size(&self, name: &str, cx: &Context) -> Size {
        match &self.defs[name] {
            Def::Struct(fields) => self.fields_size(fields, name, cx),
            Def::Enum(variants) => {
                assert!(variants.len() < 128, "tags above 127 take two bytes");
                let sizes = variants
                    .values()
                    .map(|(_, f)| self.fields_size(f, name, cx));
                let (min, max) =
                    sizes.fold((usize::MAX, 0), |acc, (a, b)| (acc.0.min(a), acc.1.max(b)));
                (1 + min, 1 + max)
            }
        }
    }

    fn type_text(&self, shape: &Shape, owner: &str, field: &str, cx: &Context) -> String {
        match shape {
            Shape::Prim(p) => prim_text(p).to_owned(),
            Shape::Str => format!("string, at most {} bytes", cx.capacity(owner, field)),
            Shape::Seq(elem) => format!(
                "sequence of at most {} {}",
                cx.capacity(owner, field),
                self.type_text(elem, owner, field, cx)
            ),
            Shape::Array(n, elem) => format!("[{}; {n}]", self.type_text(elem, owner, field, cx)),
            Shape::Tuple(items) => {
                let parts: Vec<_> = items
                    .iter()
                    .map(|s| self.type_text(s, owner, field, cx))
                    .collect();
                format!("({})", parts.join(", "))
            }
            Shape::Option(inner) => format!("Option<{}>", self.type_text(inner, owner, field, cx)),
            Shape::Unit => "()".to_owned(),
            Shape::Named(name) => format!("`{name}`"),
        }
    }

    fn field_rows(
        &self,
        fields: &Fields,
        owner: &str,
        cx: &Context,
    ) -> Vec<(String, String, String)> {
        let row = |name: String, shape: &Shape, field: &str| {
            (
                name,
                self.type_text(shape, owner, field, cx),
                bytes_text(self.size(shape, owner, field, cx)),
            )
        };
        match fields {
            Fields::Unit => vec![("-".to_owned(), "-".to_owned(), "0".to_owned())],
            Fields::Newtype(s) => vec![row("(value)".to_owned(), s, "")],
            Fields::Tuple(items) => items
                .iter()
                .enumerate()
                .map(|(i, s)| row(format!("({i})"), s, ""))
                .collect(),
            Fields::Named(items) => items
                .iter()
                .map(|(f, s)| row(format!("`{f}`"), s, f))
                .collect(),
        }
    }

    /// The Markdown tables of every recorded type, in order of first appearance.
    pub fn render(&self, cx: &Context) -> String {
        let mut out = String::new();
        for name in &self.order {
            let size = match self.type_size(name, cx) {
                (1, 1) => "1 byte".to_owned(),
                size => format!("{} bytes", bytes_text(size)),
            };
            let _ = writeln!(out, "### `{name}`\n");
            match &self.defs[name] {
                Def::Struct(Fields::Newtype(Shape::Prim(p))) if !cx.flag_bits(name).is_empty() => {
                    let _ = writeln!(
                        out,
                        "Bit set: a {}; bits without a name are kept, not refused. {size}.\n",
                        prim_text(p)
                    );
                    let _ = writeln!(out, "| bit | value | flag |\n|---:|---:|---|");
                    for (flag, bits) in cx.flag_bits(name) {
                        let _ =
                            writeln!(out, "| {} | {bits:#x} | `{flag}` |", bits.trailing_zeros());
                    }
                }
                Def::Struct(fields) => {
                    let _ = writeln!(
                        out,
                        "Struct: the fields in this order, nothing between them. {size}.\n"
                    );
                    let _ = writeln!(out, "| field | type | bytes |\n|---|---|---:|");
                    for (f, t, b) in self.field_rows(fields, name, cx) {
                        let _ = writeln!(out, "| {f} | {t} | {b} |");
                    }
                }
                Def::Enum(variants) => {
                    let _ = writeln!(
                        out,
                        "Enum: the tag (the variant index, a varint), then the variant's fields. {size}.\n"
                    );
                    let _ = writeln!(
                        out,
                        "| tag | variant | field | type | bytes |\n|---:|---|---|---|---:|"
                    );
                    for (index, (variant, fields)) in variants {
                        for (i, (f, t, b)) in
                            self.field_rows(fields, name, cx).into_iter().enumerate()
                        {
                            if i == 0 {
                                let _ =
                                    writeln!(out, "| {index} | `{variant}` | {f} | {t} | {b} |");
                            } else {
                                let _ = writeln!(out, "| | | {f} | {t} | {b} |");
                            }
                        }
                    }
                }
            }
            out.push('\n');
        }
        out
    }
}

fn bytes_text((min, max): Size) -> String {
    if min == max {
        min.to_string()
    } else {
        format!("{min}-{max}")
    }
}
