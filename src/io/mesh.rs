//! Triangle meshes for clipping (`cpu::clipmesh`): Wavefront OBJ and PLY.
//!
//! - **OBJ**: `v x y z [w]` lines give vertices, `f a b c …` lines give polygons, which
//!   are fan-triangulated `(a, b, c), (a, c, d), …`. A face index is 1-based; a
//!   negative index `−k` means the k-th vertex before this line (OBJ's relative
//!   indices); `a/t/n` keeps only `a`. Every other line (`vt`, `vn`, `o`, `g`, `s`,
//!   `usemtl`, comments) is ignored.
//! - **PLY** (ASCII or binary little-endian): the `vertex` element's `x`, `y`, `z`
//!   properties (float, double or any integer type) and the `face` element's
//!   `vertex_indices` (or `vertex_index`) list, fan-triangulated. Other elements and
//!   properties are read past and ignored.
//!
//! Coordinates are taken as they stand; the ray caster reads them as world
//! millimetres (or voxel indices with `--clip-mesh-units voxel`).
//!
//! Truncated files, NaN or infinite coordinates, indices out of range, faces with
//! fewer than three corners and absurd counts (beyond [`MAX_MESH_VERTICES`] or
//! [`MAX_MESH_TRIANGLES`], or more than the file could hold) give
//! [`Error::Format`] naming the file and the line or field; nothing panics.

use crate::error::{Error, Result};
use std::path::Path;

/// The most vertices a mesh file may declare.
pub const MAX_MESH_VERTICES: usize = 1 << 24;
/// The most triangles a mesh may have after triangulation.
pub const MAX_MESH_TRIANGLES: usize = 1 << 22;
/// The most corners one polygon may have.
const MAX_POLYGON: usize = 1 << 16;

/// An indexed triangle mesh.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TriMesh {
    pub vertices: Vec<[f64; 3]>,
    pub triangles: Vec<[u32; 3]>,
}

impl TriMesh {
    /// Checks finiteness, indices and counts (`what` names the mesh in errors).
    pub fn validate(&self, what: &Path) -> Result<()> {
        if self.vertices.len() > MAX_MESH_VERTICES {
            return Err(Error::format(what, "vertices", "too many vertices"));
        }
        if self.triangles.len() > MAX_MESH_TRIANGLES {
            return Err(Error::format(what, "faces", "too many triangles"));
        }
        if let Some(i) = self
            .vertices
            .iter()
            .position(|v| v.iter().any(|x| !x.is_finite()))
        {
            return Err(Error::format(
                what,
                format!("vertex {i}"),
                "coordinate is NaN or infinite",
            ));
        }
        let n = self.vertices.len();
        for (i, t) in self.triangles.iter().enumerate() {
            if t.iter().any(|&k| k as usize >= n) {
                return Err(Error::format(
                    what,
                    format!("triangle {i}"),
                    format!("index out of range ({n} vertices)"),
                ));
            }
        }
        Ok(())
    }

    /// The triangles' corner positions.
    pub fn triangle(&self, i: usize) -> [[f64; 3]; 3] {
        self.triangles[i].map(|k| self.vertices[k as usize])
    }

    /// An axis-aligned box `[lo, hi]` as 12 outward-facing triangles.
    pub fn cuboid(lo: [f64; 3], hi: [f64; 3]) -> TriMesh {
        let mut m = TriMesh::default();
        m.append_cuboid(lo, hi);
        m
    }

    /// Appends the 12 triangles of the box `[lo, hi]`.
    pub fn append_cuboid(&mut self, lo: [f64; 3], hi: [f64; 3]) {
        let base = self.vertices.len() as u32;
        for k in 0..8 {
            self.vertices.push([
                if k & 1 == 0 { lo[0] } else { hi[0] },
                if k & 2 == 0 { lo[1] } else { hi[1] },
                if k & 4 == 0 { lo[2] } else { hi[2] },
            ]);
        }
        // Quads of corner bits, counter-clockwise seen from outside.
        const QUADS: [[u32; 4]; 6] = [
            [0, 4, 6, 2], // −x
            [1, 3, 7, 5], // +x
            [0, 1, 5, 4], // −y
            [2, 6, 7, 3], // +y
            [0, 2, 3, 1], // −z
            [4, 5, 7, 6], // +z
        ];
        for q in QUADS {
            self.triangles.push([base + q[0], base + q[1], base + q[2]]);
            self.triangles.push([base + q[0], base + q[2], base + q[3]]);
        }
    }

    /// The mesh as OBJ text.
    pub fn to_obj(&self) -> String {
        let mut s = String::new();
        for v in &self.vertices {
            s.push_str(&format!("v {:?} {:?} {:?}\n", v[0], v[1], v[2]));
        }
        for t in &self.triangles {
            s.push_str(&format!("f {} {} {}\n", t[0] + 1, t[1] + 1, t[2] + 1));
        }
        s
    }

    /// The mesh as PLY (ASCII or binary little-endian; coordinates as doubles).
    pub fn to_ply(&self, binary: bool) -> Vec<u8> {
        let header = format!(
            "ply\nformat {} 1.0\nelement vertex {}\nproperty double x\nproperty double y\n\
             property double z\nelement face {}\nproperty list uchar int vertex_indices\nend_header\n",
            if binary { "binary_little_endian" } else { "ascii" },
            self.vertices.len(),
            self.triangles.len()
        );
        let mut out = header.into_bytes();
        for v in &self.vertices {
            if binary {
                for x in v {
                    out.extend_from_slice(&x.to_le_bytes());
                }
            } else {
                out.extend_from_slice(format!("{:?} {:?} {:?}\n", v[0], v[1], v[2]).as_bytes());
            }
        }
        for t in &self.triangles {
            if binary {
                out.push(3);
                for k in t {
                    out.extend_from_slice(&(*k as i32).to_le_bytes());
                }
            } else {
                out.extend_from_slice(format!("3 {} {} {}\n", t[0], t[1], t[2]).as_bytes());
            }
        }
        out
    }
}

/// The largest mesh file read (a 1 GiB OBJ holds some 15 million triangles).
pub const MAX_MESH_BYTES: u64 = 1 << 30;

/// Reads an OBJ (`.obj`) or PLY (`.ply`) mesh, chosen by the extension, from a regular
/// file of at most [`MAX_MESH_BYTES`].
pub fn read_mesh(path: &Path) -> Result<TriMesh> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase();
    let bytes = crate::source::read_limited(path, "clipping mesh", MAX_MESH_BYTES)?;
    match ext.as_str() {
        "obj" => parse_obj(&bytes, path),
        "ply" => parse_ply(&bytes, path),
        _ => Err(Error::format(
            path,
            "extension",
            "a clipping mesh must be .obj or .ply",
        )),
    }
}

/// Fan-triangulates a polygon of resolved vertex indices into `out`.
fn fan(poly: &[u32], out: &mut Vec<[u32; 3]>) {
    for w in poly[1..].windows(2) {
        out.push([poly[0], w[0], w[1]]);
    }
}

/// Parses OBJ text (`path` names it in errors).
pub fn parse_obj(bytes: &[u8], path: &Path) -> Result<TriMesh> {
    let text = std::str::from_utf8(bytes)
        .map_err(|e| Error::format(path, "text", format!("not UTF-8: {e}")))?;
    let mut mesh = TriMesh::default();
    let mut poly = Vec::new();
    for (ln, line) in text.lines().enumerate() {
        let at = |m: &str| Error::format(path, format!("line {}", ln + 1), m.to_string());
        let mut it = line.split_whitespace();
        match it.next() {
            Some("v") => {
                let mut v = [0.0; 3];
                for x in &mut v {
                    *x = it
                        .next()
                        .ok_or_else(|| at("a vertex needs x y z"))?
                        .parse::<f64>()
                        .map_err(|e| at(&format!("bad coordinate: {e}")))?;
                    if !x.is_finite() {
                        return Err(at("coordinate is NaN or infinite"));
                    }
                }
                if mesh.vertices.len() >= MAX_MESH_VERTICES {
                    return Err(at("too many vertices"));
                }
                mesh.vertices.push(v);
            }
            Some("f") => {
                poly.clear();
                let n = mesh.vertices.len() as i64;
                for tok in it {
                    let idx = tok.split('/').next().unwrap_or("");
                    let k: i64 = idx
                        .parse()
                        .map_err(|e| at(&format!("bad index {tok:?}: {e}")))?;
                    let r = if k > 0 { k - 1 } else { n + k };
                    if k == 0 || r < 0 || r >= n {
                        return Err(at(&format!("index {k} out of range ({n} vertices so far)")));
                    }
                    if poly.len() >= MAX_POLYGON {
                        return Err(at("polygon has too many corners"));
                    }
                    poly.push(r as u32);
                }
                if poly.len() < 3 {
                    return Err(at("a face needs at least three corners"));
                }
                if mesh.triangles.len() + poly.len() - 2 > MAX_MESH_TRIANGLES {
                    return Err(at("too many triangles"));
                }
                fan(&poly, &mut mesh.triangles);
            }
            _ => {}
        }
    }
    mesh.validate(path)?;
    Ok(mesh)
}

/// A PLY scalar type.
#[derive(Clone, Copy, Debug, PartialEq)]
enum PlyType {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl PlyType {
    fn parse(s: &str) -> Option<PlyType> {
        Some(match s {
            "char" | "int8" => PlyType::I8,
            "uchar" | "uint8" => PlyType::U8,
            "short" | "int16" => PlyType::I16,
            "ushort" | "uint16" => PlyType::U16,
            "int" | "int32" => PlyType::I32,
            "uint" | "uint32" => PlyType::U32,
            "float" | "float32" => PlyType::F32,
            "double" | "float64" => PlyType::F64,
            _ => return None,
        })
    }
    fn size(self) -> usize {
        match self {
            PlyType::I8 | PlyType::U8 => 1,
            PlyType::I16 | PlyType::U16 => 2,
            PlyType::I32 | PlyType::U32 | PlyType::F32 => 4,
            PlyType::F64 => 8,
        }
    }
    fn read_le(self, b: &[u8]) -> f64 {
        match self {
            PlyType::I8 => b[0] as i8 as f64,
            PlyType::U8 => b[0] as f64,
            PlyType::I16 => i16::from_le_bytes([b[0], b[1]]) as f64,
            PlyType::U16 => u16::from_le_bytes([b[0], b[1]]) as f64,
            PlyType::I32 => i32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
            PlyType::U32 => u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
            PlyType::F32 => f32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
            PlyType::F64 => f64::from_le_bytes(b[..8].try_into().unwrap_or([0; 8])),
        }
    }
}

/// One PLY property: a scalar, or a list with its count and item types.
#[derive(Clone, Debug)]
struct PlyProp {
    name: String,
    ty: PlyType,
    list_count: Option<PlyType>,
}

#[derive(Clone, Debug)]
struct PlyElement {
    name: String,
    count: usize,
    props: Vec<PlyProp>,
}

/// A cursor over PLY element data: whitespace tokens (ASCII) or bytes (binary).
struct PlyReader<'a> {
    data: &'a [u8],
    pos: usize,
    binary: bool,
    path: &'a Path,
}

impl PlyReader<'_> {
    fn value(&mut self, ty: PlyType, field: &str) -> Result<f64> {
        if self.binary {
            let n = ty.size();
            if self.pos + n > self.data.len() {
                return Err(Error::format(self.path, field, "file ends early"));
            }
            let v = ty.read_le(&self.data[self.pos..self.pos + n]);
            self.pos += n;
            Ok(v)
        } else {
            while self.pos < self.data.len() && self.data[self.pos].is_ascii_whitespace() {
                self.pos += 1;
            }
            let start = self.pos;
            while self.pos < self.data.len() && !self.data[self.pos].is_ascii_whitespace() {
                self.pos += 1;
            }
            if start == self.pos {
                return Err(Error::format(self.path, field, "file ends early"));
            }
            let tok = std::str::from_utf8(&self.data[start..self.pos]).unwrap_or("?");
            tok.parse::<f64>()
                .map_err(|e| Error::format(self.path, field, format!("bad number {tok:?}: {e}")))
        }
    }
}

/// Parses a PLY file (`path` names it in errors).
pub fn parse_ply(bytes: &[u8], path: &Path) -> Result<TriMesh> {
    const END: &[u8] = b"end_header";
    let end = bytes
        .windows(END.len())
        .position(|w| w == END)
        .ok_or_else(|| Error::format(path, "header", "no end_header"))?;
    let mut body = end + END.len();
    // The header ends with a newline (\n or \r\n).
    if bytes.get(body) == Some(&b'\r') {
        body += 1;
    }
    if bytes.get(body) != Some(&b'\n') {
        return Err(Error::format(
            path,
            "header",
            "end_header must end its line",
        ));
    }
    body += 1;
    let header = std::str::from_utf8(&bytes[..end])
        .map_err(|_| Error::format(path, "header", "not ASCII"))?;
    let mut lines = header.lines().map(str::trim);
    if lines.next() != Some("ply") {
        return Err(Error::format(path, "magic", "does not start with 'ply'"));
    }
    let mut binary = None;
    let mut elements: Vec<PlyElement> = Vec::new();
    for line in lines {
        let t: Vec<&str> = line.split_whitespace().collect();
        let bad = |m: &str| Error::format(path, format!("header line {line:?}"), m.to_string());
        match t.first().copied() {
            Some("format") => {
                binary = Some(match t.get(1).copied() {
                    Some("ascii") => false,
                    Some("binary_little_endian") => true,
                    Some(f) => return Err(bad(&format!("format {f} is not supported"))),
                    None => return Err(bad("format needs a value")),
                });
            }
            Some("element") => {
                let (Some(name), Some(count)) = (t.get(1), t.get(2)) else {
                    return Err(bad("element needs a name and a count"));
                };
                let count: usize = count.parse().map_err(|_| bad("bad element count"))?;
                // Every element takes at least one byte (binary) or two (ASCII).
                if count > bytes.len() || count > MAX_MESH_VERTICES.max(MAX_MESH_TRIANGLES) {
                    return Err(bad("element count is larger than the file could hold"));
                }
                elements.push(PlyElement {
                    name: name.to_string(),
                    count,
                    props: Vec::new(),
                });
            }
            Some("property") => {
                let el = elements
                    .last_mut()
                    .ok_or_else(|| bad("property before any element"))?;
                let prop = if t.get(1) == Some(&"list") {
                    let (Some(c), Some(i), Some(n)) = (t.get(2), t.get(3), t.get(4)) else {
                        return Err(bad("list property needs count type, item type, name"));
                    };
                    PlyProp {
                        name: n.to_string(),
                        ty: PlyType::parse(i).ok_or_else(|| bad("unknown type"))?,
                        list_count: Some(PlyType::parse(c).ok_or_else(|| bad("unknown type"))?),
                    }
                } else {
                    let (Some(ty), Some(n)) = (t.get(1), t.get(2)) else {
                        return Err(bad("property needs a type and a name"));
                    };
                    PlyProp {
                        name: n.to_string(),
                        ty: PlyType::parse(ty).ok_or_else(|| bad("unknown type"))?,
                        list_count: None,
                    }
                };
                el.props.push(prop);
            }
            Some("comment") | Some("obj_info") | None => {}
            Some(_) => return Err(bad("unknown header keyword")),
        }
    }
    let binary = binary.ok_or_else(|| Error::format(path, "format", "missing"))?;
    let mut r = PlyReader {
        data: bytes,
        pos: body,
        binary,
        path,
    };
    let mut mesh = TriMesh::default();
    let mut saw_vertex = false;
    let mut poly = Vec::new();
    for el in &elements {
        match el.name.as_str() {
            "vertex" => {
                saw_vertex = true;
                let axis = |n: &str| el.props.iter().position(|p| p.name == n);
                let (Some(ix), Some(iy), Some(iz)) = (axis("x"), axis("y"), axis("z")) else {
                    return Err(Error::format(path, "vertex", "needs properties x, y, z"));
                };
                if el.count > MAX_MESH_VERTICES {
                    return Err(Error::format(path, "vertex", "too many vertices"));
                }
                mesh.vertices.reserve(el.count.min(1 << 20));
                for i in 0..el.count {
                    let field = format!("vertex {i}");
                    let mut v = [0.0; 3];
                    for (k, p) in el.props.iter().enumerate() {
                        let x = read_prop(&mut r, p, &field)?;
                        if k == ix {
                            v[0] = x;
                        } else if k == iy {
                            v[1] = x;
                        } else if k == iz {
                            v[2] = x;
                        }
                    }
                    if v.iter().any(|x| !x.is_finite()) {
                        return Err(Error::format(path, field, "coordinate is NaN or infinite"));
                    }
                    mesh.vertices.push(v);
                }
            }
            "face" => {
                if !saw_vertex {
                    return Err(Error::format(path, "face", "faces before vertices"));
                }
                let Some(fi) = el
                    .props
                    .iter()
                    .position(|p| p.name == "vertex_indices" || p.name == "vertex_index")
                else {
                    return Err(Error::format(path, "face", "needs a vertex_indices list"));
                };
                let n = mesh.vertices.len();
                for i in 0..el.count {
                    let field = format!("face {i}");
                    for (k, p) in el.props.iter().enumerate() {
                        if k != fi {
                            read_prop(&mut r, p, &field)?;
                            continue;
                        }
                        let Some(ct) = p.list_count else {
                            return Err(Error::format(path, field, "vertex_indices is not a list"));
                        };
                        let c = r.value(ct, &field)?;
                        if !(3.0..=MAX_POLYGON as f64).contains(&c) || c.fract() != 0.0 {
                            return Err(Error::format(
                                path,
                                field,
                                format!("a face needs 3 to {MAX_POLYGON} corners, not {c}"),
                            ));
                        }
                        poly.clear();
                        for _ in 0..c as usize {
                            let x = r.value(p.ty, &field)?;
                            if x.fract() != 0.0 || !(0.0..n as f64).contains(&x) {
                                return Err(Error::format(
                                    path,
                                    field,
                                    format!("index {x} out of range ({n} vertices)"),
                                ));
                            }
                            poly.push(x as u32);
                        }
                        if mesh.triangles.len() + poly.len() - 2 > MAX_MESH_TRIANGLES {
                            return Err(Error::format(path, field, "too many triangles"));
                        }
                        fan(&poly, &mut mesh.triangles);
                    }
                }
            }
            _ => {
                for i in 0..el.count {
                    let field = format!("{} {i}", el.name);
                    for p in &el.props {
                        read_prop(&mut r, p, &field)?;
                    }
                }
            }
        }
    }
    if !saw_vertex {
        return Err(Error::format(path, "vertex", "no vertex element"));
    }
    mesh.validate(path)?;
    Ok(mesh)
}

/// Reads one property (a list is read whole) and returns its scalar value (0 for lists).
fn read_prop(r: &mut PlyReader, p: &PlyProp, field: &str) -> Result<f64> {
    match p.list_count {
        None => r.value(p.ty, field),
        Some(ct) => {
            let c = r.value(ct, field)?;
            if !(0.0..=MAX_POLYGON as f64).contains(&c) || c.fract() != 0.0 {
                return Err(Error::format(r.path, field, format!("bad list length {c}")));
            }
            for _ in 0..c as usize {
                r.value(p.ty, field)?;
            }
            Ok(0.0)
        }
    }
}
