//! Example sets: the rest pose and example poses of one object, sharing vertex order and
//! triangles, loaded from a folder or a TOML manifest.
//!
//! **Folder.** Every file with a mesh extension (`.obj`, `.ply`, `.gltf`, `.glb`, any case) in the
//! folder and its sub-folders; names starting with `.` are skipped, other files (e.g. a
//! `cactusBottomMask.txt`) are ignored. Order: by relative path, compared folder by folder in
//! natural order ([`natural_cmp`]: digit runs compare as numbers, letters ignore case), so
//! `poses/2.obj` comes before `poses/10.obj`. The rest pose is the file whose stem is
//! `reference` (any case; the shallowest, then first in order, if several), else the first file.
//!
//! **Manifest** (a `.toml` file; paths relative to its folder, unknown keys rejected):
//! ```toml
//! rest = "reference.obj"
//! examples = ["gallop/*.obj", "poses/*.obj"]   # globs or paths, in this order
//! control_points = [12, 400, 7]                # optional vertex indices of the rest pose
//! control_point_names = ["tip", "palm", "heel"] # optional, one per control point
//! detailed = "detailed/train.toml"             # optional: the same poses at high resolution
//! ```
//! `detailed` names another folder or manifest holding the detailed version of every example
//! (any topology, shared among the detailed examples), in the same order and with the same file
//! names; it is read by [`ExampleSet::load_detailed`] (the detail layer's training data,
//! HZY11 §4).
//! Each glob's matches are in natural order, must include at least one mesh file, and non-mesh
//! files are skipped; a file already listed (the rest, or an earlier pattern) is not repeated.
//!
//! Either way the rest pose comes first in [`ExampleSet::examples`], and every example is checked
//! against it: same vertex count, same triangles (the first differing one is named).

use std::cmp::Ordering;
use std::path::{Component, Path, PathBuf};

use serde::Deserialize;

use super::error::{Location, MeshError};
use super::{Mesh, MeshFormat};
use glam::Vec3;

/// A mesh and its name: its path relative to the set's root, `/`-separated
/// (e.g. `gallop/0001.obj`).
#[derive(Clone, Debug, PartialEq)]
pub struct NamedMesh {
    /// Path relative to [`ExampleSet::root`], `/`-separated.
    pub name: String,
    /// The mesh.
    pub mesh: Mesh,
}

/// The examples of one object: identical vertex count and triangles, rest pose first.
#[derive(Clone, Debug)]
pub struct ExampleSet {
    /// The rest (reference) pose; the same mesh as `examples[0]`.
    pub rest: Mesh,
    /// The rest pose's name (relative to `root`), e.g. `reference.obj`.
    pub rest_name: String,
    /// All frames including the rest pose, rest first, then in load order.
    pub examples: Vec<NamedMesh>,
    /// Vertex indices chosen as control points (manifest `control_points`), all in range.
    pub control_points: Option<Vec<u32>>,
    /// Names of the control points (manifest `control_point_names`), one per control point.
    pub control_point_names: Option<Vec<String>>,
    /// The folder names are relative to: the loaded folder, or the manifest's folder.
    pub root: PathBuf,
    /// The manifest's `detailed` set (resolved against `root`), if it names one.
    pub detailed: Option<PathBuf>,
}

/// Reported before each file is read by [`ExampleSet::load_with_progress`].
#[derive(Clone, Copy, Debug)]
pub struct LoadProgress<'a> {
    /// 0-based position of this file in the load order (the rest pose is 0).
    pub index: usize,
    /// How many files will be read.
    pub total: usize,
    /// The file's name relative to the root.
    pub name: &'a str,
}

/// The TOML manifest format (see the module documentation).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct Manifest {
    rest: String,
    #[serde(default)]
    examples: Vec<String>,
    #[serde(default)]
    control_points: Option<Vec<toml::Spanned<u32>>>,
    #[serde(default)]
    control_point_names: Option<toml::Spanned<Vec<String>>>,
    #[serde(default)]
    detailed: Option<String>,
}

/// Deepest folder nesting searched: guards against symbolic-link cycles.
const MAX_DEPTH: usize = 32;

/// A file to load: its display name and the path to read.
#[derive(Debug)]
struct Entry {
    name: String,
    path: PathBuf,
}

impl ExampleSet {
    /// Every example's positions, rest pose first: the frames the fitters take.
    pub fn frames(&self) -> Vec<&[Vec3]> {
        self.examples
            .iter()
            .map(|e| e.mesh.positions.as_slice())
            .collect()
    }

    /// Every example's name, rest pose first.
    pub fn names(&self) -> Vec<String> {
        self.examples.iter().map(|e| e.name.clone()).collect()
    }

    /// Loads a folder or a `.toml` manifest (see the module documentation).
    pub fn load(path: impl AsRef<Path>) -> Result<ExampleSet, MeshError> {
        Self::load_with_progress(path, |_| {})
    }

    /// Like [`ExampleSet::load`], calling `progress` before each file is read.
    pub fn load_with_progress(
        path: impl AsRef<Path>,
        mut progress: impl FnMut(LoadProgress<'_>),
    ) -> Result<ExampleSet, MeshError> {
        let path = path.as_ref();
        let meta = std::fs::metadata(path).map_err(|e| MeshError::io(path, e))?;
        let is_toml = path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("toml"));
        let (root, entries, control_points, names, detailed) = if meta.is_dir() {
            (path.to_path_buf(), folder_entries(path)?, None, None, None)
        } else if is_toml {
            manifest_entries(path)?
        } else {
            return Err(MeshError::ExampleSet {
                at: Location::file(path),
                message: "expected a folder of meshes or a .toml manifest".to_owned(),
            });
        };

        let total = entries.len();
        let mut examples = Vec::with_capacity(total);
        for (index, entry) in entries.into_iter().enumerate() {
            progress(LoadProgress {
                index,
                total,
                name: &entry.name,
            });
            let mesh = Mesh::read(&entry.path)?;
            examples.push(NamedMesh {
                name: entry.name,
                mesh,
            });
        }
        let (values, lines) = control_points.unzip();
        let lines = lines.unwrap_or_default();
        let mut set = Self::assemble(root, examples, values, |position| Location {
            path: Some(path.to_path_buf()),
            line: lines.get(position).copied().flatten(),
        })?;
        if let Some((names, line)) = names {
            let count = set.control_points.as_ref().map_or(0, Vec::len);
            if names.len() != count {
                return Err(MeshError::ExampleSet {
                    at: Location {
                        path: Some(path.to_path_buf()),
                        line: Some(line),
                    },
                    message: format!(
                        "control_point_names has {} names for {count} control points",
                        names.len()
                    ),
                });
            }
            set.control_point_names = Some(names);
        }
        set.detailed = detailed;
        Ok(set)
    }

    /// The detailed version of this set (the manifest's `detailed`), or `None` when it names
    /// none. Checked against this set: as many examples, pairwise the same file name (so pose
    /// `k` is pose `k` at both resolutions), and one topology among the detailed examples.
    pub fn load_detailed(&self) -> Result<Option<ExampleSet>, MeshError> {
        let Some(path) = &self.detailed else {
            return Ok(None);
        };
        let detailed = ExampleSet::load(path)?;
        let error = |message: String| MeshError::ExampleSet {
            at: Location::file(path),
            message,
        };
        if detailed.examples.len() != self.examples.len() {
            return Err(error(format!(
                "{} detailed examples for {} base examples",
                detailed.examples.len(),
                self.examples.len()
            )));
        }
        let file = |name: &str| name.rsplit('/').next().unwrap_or(name).to_owned();
        for (k, (b, d)) in self.examples.iter().zip(&detailed.examples).enumerate() {
            if file(&b.name) != file(&d.name) {
                return Err(error(format!(
                    "detailed example {k} is {:?}, the base example is {:?} (expected the same file name)",
                    d.name, b.name
                )));
            }
        }
        Ok(Some(detailed))
    }

    /// Builds a set from meshes already in memory; `examples[0]` is the rest pose. Checks every
    /// mesh ([`Mesh::validate`]), that all share the rest pose's vertex count and triangles, and
    /// that control points are in range. Error paths are `root` joined with the names.
    pub fn new(
        root: impl Into<PathBuf>,
        examples: Vec<NamedMesh>,
        control_points: Option<Vec<u32>>,
    ) -> Result<ExampleSet, MeshError> {
        Self::assemble(root.into(), examples, control_points, |_| {
            Location::default()
        })
    }

    fn assemble(
        root: PathBuf,
        examples: Vec<NamedMesh>,
        control_points: Option<Vec<u32>>,
        control_point_at: impl Fn(usize) -> Location,
    ) -> Result<ExampleSet, MeshError> {
        let Some(rest) = examples.first() else {
            return Err(MeshError::ExampleSet {
                at: Location::file(&root),
                message: "no meshes".to_owned(),
            });
        };
        for example in &examples {
            example
                .mesh
                .validate()
                .map_err(|e| e.in_file(&root.join(&example.name)))?;
        }
        for example in &examples[1..] {
            check_same_topology(&root, rest, example)?;
        }
        if let Some(cps) = &control_points {
            let vertex_count = rest.mesh.vertex_count();
            if let Some((position, &vertex)) = cps
                .iter()
                .enumerate()
                .find(|&(_, &v)| v as usize >= vertex_count)
            {
                return Err(MeshError::ControlPointOutOfRange {
                    at: control_point_at(position),
                    position,
                    vertex,
                    reference: rest.name.clone(),
                    vertex_count,
                });
            }
        }
        Ok(ExampleSet {
            rest: rest.mesh.clone(),
            rest_name: rest.name.clone(),
            examples,
            control_points,
            control_point_names: None,
            root,
            detailed: None,
        })
    }

    /// The file an example was loaded from: `root` joined with its name.
    pub fn path_of(&self, name: &str) -> PathBuf {
        self.root.join(name)
    }
}

/// Checks `example` has `rest`'s vertex count and triangles.
fn check_same_topology(
    root: &Path,
    rest: &NamedMesh,
    example: &NamedMesh,
) -> Result<(), MeshError> {
    let path = || root.join(&example.name);
    let (a, b) = (&example.mesh, &rest.mesh);
    if a.vertex_count() != b.vertex_count() {
        return Err(MeshError::VertexCountMismatch {
            path: path(),
            count: a.vertex_count(),
            reference: rest.name.clone(),
            expected: b.vertex_count(),
        });
    }
    if let Some((triangle, (got, expected))) = a
        .triangles
        .iter()
        .zip(&b.triangles)
        .enumerate()
        .find(|(_, (x, y))| x != y)
    {
        return Err(MeshError::TopologyMismatch {
            path: path(),
            triangle,
            got: *got,
            reference: rest.name.clone(),
            expected: *expected,
        });
    }
    if a.triangles.len() != b.triangles.len() {
        return Err(MeshError::TriangleCountMismatch {
            path: path(),
            count: a.triangles.len(),
            reference: rest.name.clone(),
            expected: b.triangles.len(),
        });
    }
    Ok(())
}

/// The mesh files of a folder tree in load order: rest first, then natural path order.
fn folder_entries(root: &Path) -> Result<Vec<Entry>, MeshError> {
    let mut entries = Vec::new();
    walk(root, "", 0, &mut entries)?;
    if entries.is_empty() {
        return Err(MeshError::ExampleSet {
            at: Location::file(root),
            message: format!(
                "no mesh files (extensions {:?}) in this folder or below",
                MeshFormat::EXTENSIONS
            ),
        });
    }
    entries.sort_by(|a, b| natural_path_cmp(&a.name, &b.name));
    let is_reference = |e: &Entry| {
        Path::new(&e.name)
            .file_stem()
            .is_some_and(|s| s.eq_ignore_ascii_case("reference"))
    };
    let depth = |e: &Entry| e.name.matches('/').count();
    let rest = entries
        .iter()
        .enumerate()
        .filter(|(_, e)| is_reference(e))
        .min_by_key(|(i, e)| (depth(e), *i))
        .map_or(0, |(i, _)| i);
    let rest = entries.remove(rest);
    entries.insert(0, rest);
    Ok(entries)
}

fn walk(dir: &Path, prefix: &str, depth: usize, out: &mut Vec<Entry>) -> Result<(), MeshError> {
    let read = std::fs::read_dir(dir).map_err(|e| MeshError::io(dir, e))?;
    for entry in read {
        let entry = entry.map_err(|e| MeshError::io(dir, e))?;
        let file_name = entry.file_name();
        let file_name = file_name.to_string_lossy();
        if file_name.starts_with('.') {
            continue;
        }
        let path = entry.path();
        // Follows symbolic links; MAX_DEPTH stops cycles.
        let meta = std::fs::metadata(&path).map_err(|e| MeshError::io(&path, e))?;
        let name = format!("{prefix}{file_name}");
        if meta.is_dir() {
            if depth < MAX_DEPTH {
                walk(&path, &format!("{name}/"), depth + 1, out)?;
            }
        } else if meta.is_file() && MeshFormat::detect(&path).is_some() {
            out.push(Entry { name, path });
        }
    }
    Ok(())
}

/// Control point values and the TOML line of each.
type ControlPoints = Option<(Vec<u32>, Vec<Option<usize>>)>;
/// Control point names and the TOML line of the list.
type ControlNames = Option<(Vec<String>, usize)>;

/// A manifest's parts: the root (its folder), the files in load order, the control points, their
/// names, and the detailed set.
type ManifestParts = (
    PathBuf,
    Vec<Entry>,
    ControlPoints,
    ControlNames,
    Option<PathBuf>,
);

/// Reads a manifest (see [`ManifestParts`]).
fn manifest_entries(manifest_path: &Path) -> Result<ManifestParts, MeshError> {
    let text =
        std::fs::read_to_string(manifest_path).map_err(|e| MeshError::io(manifest_path, e))?;
    let line_of = |offset: usize| text[..offset.min(text.len())].matches('\n').count() + 1;
    let manifest: Manifest = toml::from_str(&text).map_err(|e| MeshError::ExampleSet {
        at: Location {
            path: Some(manifest_path.to_path_buf()),
            line: e.span().map(|s| line_of(s.start)),
        },
        message: e.message().trim().to_owned(),
    })?;
    let root = manifest_path
        .parent()
        .unwrap_or(Path::new(""))
        .to_path_buf();
    let at = || Location::file(manifest_path);

    let rest_path = root.join(&manifest.rest);
    let mut seen = vec![identity(&rest_path)];
    let mut entries = vec![Entry {
        name: slash_name(Path::new(&manifest.rest)),
        path: rest_path,
    }];
    for (k, pattern) in manifest.examples.iter().enumerate() {
        let is_glob = pattern.contains(['*', '?', '[']);
        let mut matched: Vec<Entry> = Vec::new();
        if is_glob {
            let root_str = root.to_str().ok_or_else(|| MeshError::ExampleSet {
                at: at(),
                message: format!("folder {} is not valid UTF-8", root.display()),
            })?;
            let full = if root_str.is_empty() {
                pattern.clone()
            } else {
                format!("{}/{pattern}", glob::Pattern::escape(root_str))
            };
            let options = glob::MatchOptions {
                require_literal_leading_dot: true,
                ..glob::MatchOptions::new()
            };
            let paths = glob::glob_with(&full, options).map_err(|e| MeshError::ExampleSet {
                at: at(),
                message: format!("examples[{k}] = {pattern:?}: {e}"),
            })?;
            for path in paths {
                let path = path.map_err(|e| {
                    let failed = e.path().to_path_buf();
                    MeshError::io(&failed, e.into())
                })?;
                if path.is_file() && MeshFormat::detect(&path).is_some() {
                    let name = slash_name(path.strip_prefix(&root).unwrap_or(&path));
                    matched.push(Entry { name, path });
                }
            }
            if matched.is_empty() {
                return Err(MeshError::ExampleSet {
                    at: at(),
                    message: format!("examples[{k}] = {pattern:?} matched no mesh files"),
                });
            }
            matched.sort_by(|a, b| natural_path_cmp(&a.name, &b.name));
        } else {
            matched.push(Entry {
                name: slash_name(Path::new(pattern)),
                path: root.join(pattern),
            });
        }
        for entry in matched {
            let id = identity(&entry.path);
            if !seen.contains(&id) {
                seen.push(id);
                entries.push(entry);
            }
        }
    }
    let cps = manifest.control_points.map(|cps| {
        cps.iter()
            .map(|c| (*c.get_ref(), Some(line_of(c.span().start))))
            .unzip()
    });
    let names = manifest
        .control_point_names
        .map(|n| (n.get_ref().clone(), line_of(n.span().start)));
    let detailed = manifest.detailed.map(|d| root.join(d));
    Ok((root, entries, cps, names, detailed))
}

/// The path by which duplicates are recognised: canonical when the file exists (so
/// `./a.obj` and `a.obj` are one file), as given otherwise (the read will report it missing).
fn identity(path: &Path) -> PathBuf {
    std::fs::canonicalize(path).unwrap_or_else(|_| path.to_path_buf())
}

/// A relative path as a `/`-separated name, `.` components dropped.
fn slash_name(path: &Path) -> String {
    let parts: Vec<String> = path
        .components()
        .filter(|c| !matches!(c, Component::CurDir))
        .map(|c| c.as_os_str().to_string_lossy().into_owned())
        .collect();
    parts.join("/")
}

/// Natural order of two names: runs of ASCII digits compare by numeric value (`2 < 10`,
/// leading zeros ignored), other characters one by one ignoring ASCII case. Ties (`"01"` vs
/// `"1"`, `"A"` vs `"a"`) fall back to byte order, so the order is total.
pub fn natural_cmp(a: &str, b: &str) -> Ordering {
    let (x, y) = (a.as_bytes(), b.as_bytes());
    let (mut i, mut j) = (0, 0);
    while i < x.len() && j < y.len() {
        if x[i].is_ascii_digit() && y[j].is_ascii_digit() {
            let (si, sj) = (i, j);
            while i < x.len() && x[i].is_ascii_digit() {
                i += 1;
            }
            while j < y.len() && y[j].is_ascii_digit() {
                j += 1;
            }
            let nx = trim_zeros(&x[si..i]);
            let ny = trim_zeros(&y[sj..j]);
            let ord = nx.len().cmp(&ny.len()).then_with(|| nx.cmp(ny));
            if ord != Ordering::Equal {
                return ord;
            }
        } else {
            let ord = x[i].to_ascii_lowercase().cmp(&y[j].to_ascii_lowercase());
            if ord != Ordering::Equal {
                return ord;
            }
            i += 1;
            j += 1;
        }
    }
    (x.len() - i).cmp(&(y.len() - j)).then_with(|| a.cmp(b))
}

fn trim_zeros(digits: &[u8]) -> &[u8] {
    let first = digits
        .iter()
        .position(|&d| d != b'0')
        .unwrap_or(digits.len());
    &digits[first..]
}

/// Natural order of `/`-separated relative paths, folder by folder ([`natural_cmp`] on each
/// component): `a/b.obj` sorts with the other contents of `a`, before `a.obj`.
pub fn natural_path_cmp(a: &str, b: &str) -> Ordering {
    let mut x = a.split('/');
    let mut y = b.split('/');
    loop {
        match (x.next(), y.next()) {
            (None, None) => return Ordering::Equal,
            (None, Some(_)) => return Ordering::Less,
            (Some(_), None) => return Ordering::Greater,
            (Some(p), Some(q)) => {
                let ord = natural_cmp(p, q);
                if ord != Ordering::Equal {
                    return ord;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    #[test]
    fn natural_order_of_names() {
        let mut names = vec![
            "poses/10.obj",
            "poses/2.obj",
            "poses/1.obj",
            "gallop/0010.obj",
            "gallop/0002.obj",
            "reference.obj",
            "cactus10.ply",
            "cactus2.ply",
            "Cactus3.ply",
            "a.obj",
            "a1.obj",
        ];
        names.sort_by(|a, b| natural_path_cmp(a, b));
        assert_eq!(
            names,
            vec![
                "a.obj",
                "a1.obj",
                "cactus2.ply",
                "Cactus3.ply",
                "cactus10.ply",
                "gallop/0002.obj",
                "gallop/0010.obj",
                "poses/1.obj",
                "poses/2.obj",
                "poses/10.obj",
                "reference.obj",
            ]
        );
    }

    #[test]
    fn natural_cmp_is_total_on_ties() {
        assert_eq!(natural_cmp("01", "1"), Ordering::Less);
        assert_eq!(natural_cmp("1", "01"), Ordering::Greater);
        assert_eq!(natural_cmp("A", "a"), Ordering::Less);
        assert_eq!(natural_cmp("x", "x"), Ordering::Equal);
        assert_eq!(natural_cmp("x9", "x10"), Ordering::Less);
        assert_eq!(natural_cmp("x", "x0"), Ordering::Less);
        // A number longer than u64 still compares.
        assert_eq!(
            natural_cmp("99999999999999999999999", "100000000000000000000000"),
            Ordering::Less
        );
    }

    fn tri(shift: f32) -> Mesh {
        Mesh {
            positions: vec![Vec3::ZERO, Vec3::X, Vec3::splat(shift)],
            triangles: vec![[0, 1, 2], [2, 1, 0]],
        }
    }

    fn named(name: &str, mesh: Mesh) -> NamedMesh {
        NamedMesh {
            name: name.to_owned(),
            mesh,
        }
    }

    #[test]
    fn new_checks_counts_topology_and_control_points() {
        let ok = ExampleSet::new(
            "set",
            vec![named("r.obj", tri(1.0)), named("a.obj", tri(2.0))],
            Some(vec![2, 0]),
        )
        .unwrap();
        assert_eq!(ok.rest_name, "r.obj");
        assert_eq!(ok.rest, ok.examples[0].mesh);
        assert_eq!(ok.path_of("a.obj"), Path::new("set").join("a.obj"));

        let mut other = tri(2.0);
        other.triangles[1] = [2, 0, 1];
        let e = ExampleSet::new(
            "set",
            vec![named("r.obj", tri(1.0)), named("b.obj", other)],
            None,
        )
        .unwrap_err();
        let b = Path::new("set").join("b.obj");
        assert_eq!(
            e.to_string(),
            format!(
                "{}: triangle 1 is [2, 0, 1], r.obj has [2, 1, 0]",
                b.display()
            )
        );

        let mut more = tri(2.0);
        more.triangles.push([0, 1, 2]);
        let e = ExampleSet::new(
            "set",
            vec![named("r.obj", tri(1.0)), named("b.obj", more)],
            None,
        )
        .unwrap_err();
        assert_eq!(
            e.to_string(),
            format!("{}: 3 triangles, r.obj has 2", b.display())
        );

        let mut fewer = tri(2.0);
        fewer.positions.pop();
        fewer.triangles.clear();
        let e = ExampleSet::new(
            "set",
            vec![named("r.obj", tri(1.0)), named("b.obj", fewer)],
            None,
        )
        .unwrap_err();
        assert_eq!(
            e.to_string(),
            format!("{}: 2 vertices, r.obj has 3", b.display())
        );

        let e =
            ExampleSet::new("set", vec![named("r.obj", tri(1.0))], Some(vec![1, 3])).unwrap_err();
        assert_eq!(
            e.to_string(),
            "in-memory mesh: control_points[1] = 3 is out of range (r.obj has 3 vertices)"
        );

        let mut nan = tri(2.0);
        nan.positions[1].y = f32::NAN;
        let e = ExampleSet::new(
            "set",
            vec![named("r.obj", tri(1.0)), named("n.obj", nan)],
            None,
        )
        .unwrap_err();
        assert!(e.to_string().contains("vertex 1 has a non-finite y"), "{e}");
        assert!(e.to_string().contains("n.obj"), "{e}");

        assert!(ExampleSet::new("set", vec![], None).is_err());
    }
}
