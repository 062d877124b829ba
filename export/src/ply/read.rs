//! PLY reading: header checks, element-by-element parsing through `ply_rs_bw::parser`, and the
//! validation that turns a parsed file into trusted mesh data.

use std::io::{self, BufRead};

use nalgebra::{Point3, Vector3};
use ply_rs_bw::parser::{ParseError, Parser, Reader};
use ply_rs_bw::ply::{
    BeginList, ElementDef, Encoding, Header, PropertyAccess, PropertyAccessResult, PropertyType,
    ScalarType,
};

use super::PlyError;

/// Upper bound on up-front allocation from header counts: a corrupt header must not make us
/// reserve gigabytes before the data proves it exists. Vectors grow past it as data arrives.
const MAX_PREALLOCATED: usize = 1 << 16;

/// Longest parser message we quote (some quote a whole line of the input).
const MAX_MESSAGE_CHARS: usize = 240;

/// Vertex data read from a file, already validated.
#[derive(Debug, Default)]
pub(super) struct PlyData {
    pub positions: Vec<Point3<f32>>,
    pub normals: Vec<Vector3<f32>>,
    pub colors: Vec<[u8; 3]>,
    pub faces: Vec<[u32; 3]>,
}

/// Slots of a vertex record: position 0..3, normal 3..6, colour 6..9.
fn vertex_slot(name: &str) -> Option<usize> {
    Some(match name {
        "x" => 0,
        "y" => 1,
        "z" => 2,
        "nx" | "normal_x" => 3,
        "ny" | "normal_y" => 4,
        "nz" | "normal_z" => 5,
        "red" | "diffuse_red" => 6,
        "green" | "diffuse_green" => 7,
        "blue" | "diffuse_blue" => 8,
        _ => return None,
    })
}

const SLOT_NAMES: [&str; 9] = ["x", "y", "z", "nx", "ny", "nz", "red", "green", "blue"];

fn is_index_list(name: &str) -> bool {
    name == "vertex_indices" || name == "vertex_index"
}

fn is_integer(t: &ScalarType) -> bool {
    !matches!(t, ScalarType::Float | ScalarType::Double)
}

fn type_name(t: &ScalarType) -> &'static str {
    match t {
        ScalarType::Char => "char",
        ScalarType::UChar => "uchar",
        ScalarType::Short => "short",
        ScalarType::UShort => "ushort",
        ScalarType::Int => "int",
        ScalarType::UInt => "uint",
        ScalarType::Float => "float",
        ScalarType::Double => "double",
    }
}

/// How colour values are stored.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum ColorKind {
    /// 0..=255.
    U8,
    /// 0..=65535; scaled to 8 bits.
    U16,
    /// 0.0..=1.0; scaled to 8 bits and clamped.
    Unit,
}

/// What the header promises, checked before any payload is read.
#[derive(Debug)]
struct Layout {
    vertex_count: usize,
    has_normals: bool,
    colors: Option<ColorKind>,
    /// Element type of the face index list, when the file has faces to read.
    face_index_type: Option<ScalarType>,
}

impl Layout {
    fn from_header(header: &Header, file: &str, want_faces: bool) -> Result<Self, PlyError> {
        let layout_error = |message: String| PlyError::Layout {
            file: file.to_owned(),
            message,
        };
        for (name, def) in &header.elements {
            if def.count > 0 && def.properties.is_empty() {
                return Err(layout_error(format!(
                    "element '{name}' declares {} items but no properties",
                    def.count
                )));
            }
        }
        let vertex = header
            .elements
            .get("vertex")
            .ok_or_else(|| layout_error("the file has no 'vertex' element".to_owned()))?;
        if vertex.count > u32::MAX as usize {
            return Err(layout_error(format!(
                "{} vertices are more than 32-bit indices can address",
                vertex.count
            )));
        }
        let mut found: [Option<(&str, &ScalarType)>; 9] = [None; 9];
        for (name, prop) in &vertex.properties {
            let Some(slot) = vertex_slot(name) else {
                continue;
            };
            let PropertyType::Scalar(t) = &prop.data_type else {
                return Err(layout_error(format!(
                    "vertex property '{name}' is a list; expected a number"
                )));
            };
            if let Some((other, _)) = found[slot] {
                return Err(layout_error(format!(
                    "vertex has both '{other}' and '{name}'"
                )));
            }
            found[slot] = Some((name, t));
        }
        for (slot, name) in SLOT_NAMES.iter().enumerate().take(3) {
            if found[slot].is_none() {
                return Err(layout_error(format!(
                    "the vertex element has no '{name}' property"
                )));
            }
        }
        let complete = |range: std::ops::Range<usize>, what: &str| -> Result<bool, PlyError> {
            let present = found[range.clone()].iter().filter(|f| f.is_some()).count();
            match present {
                0 => Ok(false),
                3 => Ok(true),
                _ => Err(layout_error(format!(
                    "the vertex element has only {present} of the 3 {what} properties"
                ))),
            }
        };
        let has_normals = complete(3..6, "normal")?;
        let colors = if complete(6..9, "colour")? {
            let mut kind = None;
            for (name, t) in found[6..9].iter().flatten() {
                let k = match t {
                    ScalarType::UChar => ColorKind::U8,
                    ScalarType::UShort => ColorKind::U16,
                    ScalarType::Float | ScalarType::Double => ColorKind::Unit,
                    other => {
                        return Err(layout_error(format!(
                            "vertex colour '{name}' has type {}; expected uchar, ushort, float or double",
                            type_name(other)
                        )));
                    }
                };
                if kind.is_some_and(|previous| previous != k) {
                    return Err(layout_error(
                        "the vertex colour properties have different types".to_owned(),
                    ));
                }
                kind = Some(k);
            }
            kind
        } else {
            None
        };

        let mut face_index_type = None;
        if let Some(face) = header.elements.get("face").filter(|_| want_faces) {
            let lists: Vec<_> = face
                .properties
                .iter()
                .filter(|(name, _)| is_index_list(name))
                .collect();
            match lists.as_slice() {
                [] if face.count == 0 => {}
                [] => {
                    return Err(layout_error(
                        "the face element has no 'vertex_indices' property".to_owned(),
                    ));
                }
                [(name, prop)] => match &prop.data_type {
                    PropertyType::List(count_type, index_type)
                        if is_integer(count_type) && is_integer(index_type) =>
                    {
                        face_index_type = Some(index_type.clone());
                    }
                    PropertyType::List(count_type, index_type) => {
                        return Err(layout_error(format!(
                            "face property '{name}' is a list of {} counted by {}; both must be integers",
                            type_name(index_type),
                            type_name(count_type)
                        )));
                    }
                    PropertyType::Scalar(_) => {
                        return Err(layout_error(format!(
                            "face property '{name}' is a number; expected a list of vertex indices"
                        )));
                    }
                },
                _ => {
                    return Err(layout_error(
                        "the face element has both 'vertex_indices' and 'vertex_index'".to_owned(),
                    ));
                }
            }
        }
        Ok(Self {
            vertex_count: vertex.count,
            has_normals,
            colors,
            face_index_type,
        })
    }
}

/// A vertex as parsed: every recognised property as f64 (exact for all PLY scalar types).
#[derive(Debug, Default)]
struct VertexRecord {
    values: [f64; 9],
}

impl VertexRecord {
    fn set(&mut self, name: &str, value: f64) -> PropertyAccessResult {
        match vertex_slot(name) {
            Some(slot) => {
                self.values[slot] = value;
                PropertyAccessResult::Set
            }
            None => PropertyAccessResult::Ignored,
        }
    }
}

impl PropertyAccess for VertexRecord {
    fn new() -> Self {
        Self::default()
    }
    fn set_char(&mut self, name: &str, value: i8) -> PropertyAccessResult {
        self.set(name, f64::from(value))
    }
    fn set_uchar(&mut self, name: &str, value: u8) -> PropertyAccessResult {
        self.set(name, f64::from(value))
    }
    fn set_short(&mut self, name: &str, value: i16) -> PropertyAccessResult {
        self.set(name, f64::from(value))
    }
    fn set_ushort(&mut self, name: &str, value: u16) -> PropertyAccessResult {
        self.set(name, f64::from(value))
    }
    fn set_int(&mut self, name: &str, value: i32) -> PropertyAccessResult {
        self.set(name, f64::from(value))
    }
    fn set_uint(&mut self, name: &str, value: u32) -> PropertyAccessResult {
        self.set(name, f64::from(value))
    }
    fn set_float(&mut self, name: &str, value: f32) -> PropertyAccessResult {
        self.set(name, f64::from(value))
    }
    fn set_double(&mut self, name: &str, value: f64) -> PropertyAccessResult {
        self.set(name, value)
    }
}

/// A face as parsed: the index list lands in the vector of its declared type.
#[derive(Debug, Default)]
struct FaceRecord {
    i8s: Vec<i8>,
    u8s: Vec<u8>,
    i16s: Vec<i16>,
    u16s: Vec<u16>,
    i32s: Vec<i32>,
    u32s: Vec<u32>,
}

impl FaceRecord {
    /// The corners as i64 (exact for every integer type), into `out`.
    fn corners_into(&self, index_type: &ScalarType, out: &mut Vec<i64>) {
        out.clear();
        match index_type {
            ScalarType::Char => out.extend(self.i8s.iter().map(|&v| i64::from(v))),
            ScalarType::UChar => out.extend(self.u8s.iter().map(|&v| i64::from(v))),
            ScalarType::Short => out.extend(self.i16s.iter().map(|&v| i64::from(v))),
            ScalarType::UShort => out.extend(self.u16s.iter().map(|&v| i64::from(v))),
            ScalarType::Int => out.extend(self.i32s.iter().map(|&v| i64::from(v))),
            ScalarType::UInt => out.extend(self.u32s.iter().map(|&v| i64::from(v))),
            // Layout::from_header only admits integer index types.
            ScalarType::Float | ScalarType::Double => {}
        }
    }
}

macro_rules! fill_index_list {
    ($method:ident, $field:ident, $t:ty) => {
        fn $method(&mut self, name: &str, _len: usize) -> BeginList<'_, $t> {
            if is_index_list(name) {
                BeginList::Fill(&mut self.$field)
            } else {
                BeginList::UseSetter
            }
        }
    };
}

impl PropertyAccess for FaceRecord {
    fn new() -> Self {
        Self::default()
    }
    fill_index_list!(begin_list_char, i8s, i8);
    fill_index_list!(begin_list_uchar, u8s, u8);
    fill_index_list!(begin_list_short, i16s, i16);
    fill_index_list!(begin_list_ushort, u16s, u16);
    fill_index_list!(begin_list_int, i32s, i32);
    fill_index_list!(begin_list_uint, u32s, u32);
}

/// An element whose content we do not need; it is parsed and dropped.
#[derive(Debug)]
struct Skip;

impl PropertyAccess for Skip {
    fn new() -> Self {
        Skip
    }
}

/// A parser message on one line, cut to a readable length.
fn flatten(message: &str) -> String {
    let one_line: String = message
        .split(['\n', '\t'])
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .collect::<Vec<_>>()
        .join("; ");
    if one_line.chars().count() > MAX_MESSAGE_CHARS {
        let cut: String = one_line.chars().take(MAX_MESSAGE_CHARS).collect();
        format!("{cut}…")
    } else {
        one_line
    }
}

/// The payload cursor: the stream after the header, its encoding and the current line.
struct Payload<'a, R: BufRead> {
    reader: &'a mut Reader<R>,
    encoding: Encoding,
    file: &'a str,
    /// 1-based number of the next ASCII line.
    next_line: usize,
    line: String,
}

impl<R: BufRead> Payload<'_, R> {
    /// Reads all `def.count` elements, handing each to `sink` with its index.
    fn read_elements<E: PropertyAccess>(
        &mut self,
        def: &ElementDef,
        mut sink: impl FnMut(usize, E) -> Result<(), PlyError>,
    ) -> Result<(), PlyError> {
        let parser = Parser::<E>::new();
        for index in 0..def.count {
            let record = match self.encoding {
                Encoding::Ascii => self.read_ascii(&parser, def, index)?,
                Encoding::BinaryLittleEndian => {
                    let r = parser.read_little_endian_element(self.reader.get_mut(), def);
                    self.binary_result(r, def, index)?
                }
                Encoding::BinaryBigEndian => {
                    let r = parser.read_big_endian_element(self.reader.get_mut(), def);
                    self.binary_result(r, def, index)?
                }
            };
            sink(index, record)?;
        }
        Ok(())
    }

    fn truncated(&self, def: &ElementDef, read: usize, note: &'static str) -> PlyError {
        PlyError::Truncated {
            file: self.file.to_owned(),
            element: def.name.clone(),
            expected: def.count,
            read,
            note,
        }
    }

    fn malformed(
        &self,
        def: &ElementDef,
        index: usize,
        line: Option<usize>,
        message: String,
    ) -> PlyError {
        PlyError::Malformed {
            file: self.file.to_owned(),
            element: def.name.clone(),
            index,
            line,
            message,
        }
    }

    fn binary_result<E>(
        &self,
        result: Result<E, ParseError>,
        def: &ElementDef,
        index: usize,
    ) -> Result<E, PlyError> {
        result.map_err(|e| {
            if e.kind() == io::ErrorKind::UnexpectedEof {
                self.truncated(def, index, "")
            } else {
                self.malformed(def, index, None, flatten(&e.to_string()))
            }
        })
    }

    fn read_ascii<E: PropertyAccess>(
        &mut self,
        parser: &Parser<E>,
        def: &ElementDef,
        index: usize,
    ) -> Result<E, PlyError> {
        // Blank lines carry no element; skip them.
        let line_number = loop {
            self.line.clear();
            let n = self
                .reader
                .get_mut()
                .read_line(&mut self.line)
                .map_err(|e| match e.kind() {
                    io::ErrorKind::InvalidData => self.malformed(
                        def,
                        index,
                        Some(self.next_line),
                        "the line is not valid text".to_owned(),
                    ),
                    _ => PlyError::Io {
                        file: self.file.to_owned(),
                        source: e,
                    },
                })?;
            if n == 0 {
                return Err(self.truncated(def, index, ""));
            }
            self.next_line += 1;
            if !self.line.trim().is_empty() {
                break self.next_line - 1;
            }
        };
        // Without its line break the last line may be cut anywhere, even inside a number
        // that still parses; a complete file ends every line.
        if !self.line.ends_with('\n') {
            return Err(self.truncated(
                def,
                index,
                " (the last line has no line break, so it may be cut short)",
            ));
        }
        if let Some(extra) = extra_ascii_values(&self.line, def) {
            return Err(self.malformed(
                def,
                index,
                Some(line_number),
                format!("{extra} more values than the header declares"),
            ));
        }
        parser
            .read_ascii_element(&self.line, def)
            .map_err(|e| self.malformed(def, index, Some(line_number), flatten(&e.to_string())))
    }

    /// Checks that only whitespace follows the last element.
    fn check_trailing(&mut self) -> Result<(), PlyError> {
        let reader = self.reader.get_mut();
        let (mut total, mut junk) = (0usize, false);
        loop {
            let buf = reader.fill_buf().map_err(|source| PlyError::Io {
                file: self.file.to_owned(),
                source,
            })?;
            if buf.is_empty() {
                break;
            }
            junk |= buf.iter().any(|b| !b.is_ascii_whitespace());
            let n = buf.len();
            total += n;
            reader.consume(n);
        }
        if junk {
            return Err(PlyError::TrailingData {
                file: self.file.to_owned(),
                bytes: total,
            });
        }
        Ok(())
    }
}

/// How many values an ASCII element line has beyond what the header declares, if any. Lines
/// with too few values (or unparsable list counts) are left to the parser to report.
fn extra_ascii_values(line: &str, def: &ElementDef) -> Option<usize> {
    let mut tokens = line.split_ascii_whitespace();
    for prop in def.properties.values() {
        match prop.data_type {
            PropertyType::Scalar(_) => {
                tokens.next()?;
            }
            PropertyType::List(..) => {
                let count: usize = tokens.next()?.parse().ok()?;
                if count > 0 {
                    tokens.nth(count - 1)?;
                }
            }
        }
    }
    match tokens.count() {
        0 => None,
        n => Some(n),
    }
}

fn to_u8_color(value: f64, kind: ColorKind) -> u8 {
    // `as u8` saturates (and maps NaN to 0), so any input gives a valid byte.
    match kind {
        ColorKind::U8 => value as u8,
        ColorKind::U16 => (value / 257.0).round() as u8,
        ColorKind::Unit => (value.clamp(0.0, 1.0) * 255.0).round() as u8,
    }
}

/// Reads a whole PLY stream. With `want_faces = false` faces are parsed but not kept.
pub(super) fn read_ply<R: BufRead>(
    reader: R,
    file: &str,
    want_faces: bool,
) -> Result<PlyData, PlyError> {
    let mut reader = Reader::new(reader);
    let header = Parser::<Skip>::new()
        .read_header(&mut reader)
        .map_err(|e| PlyError::Header {
            file: file.to_owned(),
            message: flatten(&e.to_string()),
        })?;
    let layout = Layout::from_header(&header, file, want_faces)?;

    let mut data = PlyData::default();
    let capacity = layout.vertex_count.min(MAX_PREALLOCATED);
    data.positions.reserve(capacity);
    if layout.has_normals {
        data.normals.reserve(capacity);
    }
    if layout.colors.is_some() {
        data.colors.reserve(capacity);
    }

    let next_line = reader.line().max(1);
    let mut payload = Payload {
        reader: &mut reader,
        encoding: header.encoding,
        file,
        next_line,
        line: String::new(),
    };
    let mut corners = Vec::<i64>::new();
    for (name, def) in &header.elements {
        if name == "vertex" {
            payload.read_elements::<VertexRecord>(def, |i, record| {
                push_vertex(&mut data, &layout, file, i, &record.values)
            })?;
        } else if let (true, Some(index_type)) = (name == "face", &layout.face_index_type) {
            data.faces.reserve(def.count.min(MAX_PREALLOCATED));
            payload.read_elements::<FaceRecord>(def, |i, record| {
                record.corners_into(index_type, &mut corners);
                push_face(&mut data.faces, &corners, layout.vertex_count, file, i)
            })?;
        } else {
            payload.read_elements::<Skip>(def, |_, _| Ok(()))?;
        }
    }
    payload.check_trailing()?;
    Ok(data)
}

fn push_vertex(
    data: &mut PlyData,
    layout: &Layout,
    file: &str,
    vertex: usize,
    v: &[f64; 9],
) -> Result<(), PlyError> {
    let finite = |values: &[f64], attribute: &'static str| -> Result<[f32; 3], PlyError> {
        let mut out = [0.0f32; 3];
        for (o, &value) in out.iter_mut().zip(values) {
            // Rounding to f32 can overflow a finite double to infinity; check after it.
            *o = value as f32;
            if !o.is_finite() {
                return Err(PlyError::NotFinite {
                    file: file.to_owned(),
                    vertex,
                    attribute,
                    value,
                });
            }
        }
        Ok(out)
    };
    let [x, y, z] = finite(&v[0..3], "position")?;
    data.positions.push(Point3::new(x, y, z));
    if layout.has_normals {
        let [x, y, z] = finite(&v[3..6], "normal")?;
        data.normals.push(Vector3::new(x, y, z));
    }
    if let Some(kind) = layout.colors {
        data.colors.push([
            to_u8_color(v[6], kind),
            to_u8_color(v[7], kind),
            to_u8_color(v[8], kind),
        ]);
    }
    Ok(())
}

/// Checks one polygon and appends its fan triangulation.
fn push_face(
    faces: &mut Vec<[u32; 3]>,
    corners: &[i64],
    vertex_count: usize,
    file: &str,
    face: usize,
) -> Result<(), PlyError> {
    if corners.len() < 3 {
        return Err(PlyError::DegenerateFace {
            file: file.to_owned(),
            face,
            corners: corners.len(),
        });
    }
    let index = |i: i64| -> Result<u32, PlyError> {
        match u32::try_from(i) {
            Ok(u) if (u as usize) < vertex_count => Ok(u),
            _ => Err(PlyError::FaceIndexOutOfRange {
                file: file.to_owned(),
                face,
                index: i,
                vertex_count,
            }),
        }
    };
    if let [a, b, c] = *corners {
        faces.push([index(a)?, index(b)?, index(c)?]);
        return Ok(());
    }
    let checked = corners
        .iter()
        .map(|&c| index(c))
        .collect::<Result<Vec<u32>, _>>()?;
    for pair in checked[1..].windows(2) {
        faces.push([checked[0], pair[0], pair[1]]);
    }
    Ok(())
}
