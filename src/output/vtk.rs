//! VTK output for ParaView: one `.vtu` (XML unstructured grid, binary appended data) per
//! saved level and one `.pvd` collection that lists them with their times.
//!
//! **One point per node**, shared by the elements that meet there (each element is a
//! `VTK_LINE` cell between its two nodes), then one extra point per rigid-link pivot (each
//! link is a line cell pivot → node). Point data: `node_id`, `rod_id` (Int64; −1 for
//! pivots), `displacement` (from the reference configuration), `velocity` and the node
//! directors `d1, d2, d3` (the triad of the lowest-numbered element at the node, as in
//! `trajectory.npz`; zero at pivots). Cell data: `element_id`, `rod_id` (−1 for links),
//! `link` (1 for rigid-link cells), the strains `strain_Gamma` = Γ − Γ₀, `strain_Omega` =
//! Ω − Ω₀ and the stress resultants `N = C_Γ(Γ − Γ₀)`, `M = C_Ω(Ω − Ω₀)` in the director
//! basis (zero on link cells).
//!
//! The arrays are written in VTK's `AppendedData` section, `encoding="raw"`, little endian,
//! `header_type="UInt64"`: each array is an 8-byte byte count followed by its values, at
//! the `offset` its `DataArray` tag names (counted from the byte after the `_` marker).
//! Written by hand: the format is small and fixed, and a VTK crate would pull in far more
//! than these few arrays need.

use std::fmt::Write as _;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use super::OutputError;
use crate::integrator::Simulation;
use crate::model::Vec3;
use crate::observe::probe::node_director_ends;

/// The collection file is rewritten after this many frames (an interrupted run keeps a
/// valid collection of most of its frames without rewriting it after every frame).
pub const PVD_EVERY: usize = 64;

/// Writes `NAME_000042.vtu` files into a folder and `NAME.pvd` on [`finish`](Self::finish)
/// (and every `PVD_EVERY` frames).
#[derive(Debug)]
pub struct VtkSeries {
    dir: PathBuf,
    name: String,
    frames: Vec<(f64, String)>,
}

impl VtkSeries {
    /// A series in `dir` (created if missing) with file names starting with `name`.
    pub fn new(dir: &Path, name: &str) -> Result<Self, OutputError> {
        std::fs::create_dir_all(dir).map_err(|e| OutputError::io(dir, e))?;
        Ok(Self {
            dir: dir.to_path_buf(),
            name: name.to_string(),
            frames: Vec::new(),
        })
    }

    /// Writes the current level of `sim` as the frame of `step` at time `t`.
    pub fn write_frame(
        &mut self,
        sim: &Simulation,
        step: usize,
        t: f64,
    ) -> Result<(), OutputError> {
        let file = format!("{}_{step:06}.vtu", self.name);
        let path = self.dir.join(&file);
        let bytes = vtu_bytes(sim);
        let f = File::create(&path).map_err(|e| OutputError::io(&path, e))?;
        let mut w = BufWriter::new(f);
        w.write_all(&bytes)
            .and_then(|()| w.flush())
            .map_err(|e| OutputError::io(&path, e))?;
        self.frames.push((t, file));
        if self.frames.len().is_multiple_of(PVD_EVERY) {
            self.write_pvd()?;
        }
        Ok(())
    }

    /// Writes the `.pvd` collection of all frames written (through a temporary file
    /// renamed over it: the collection on disk is always whole).
    pub fn finish(&self) -> Result<(), OutputError> {
        self.write_pvd()
    }

    /// Path of the `.pvd` collection.
    pub fn pvd_path(&self) -> PathBuf {
        self.dir.join(self.pvd_file_name())
    }

    /// File name of the `.pvd` collection.
    pub fn pvd_file_name(&self) -> String {
        format!("{}.pvd", self.name)
    }

    /// Number of frames written.
    pub fn frames(&self) -> usize {
        self.frames.len()
    }

    fn write_pvd(&self) -> Result<(), OutputError> {
        let mut s = String::from(
            "<?xml version=\"1.0\"?>\n<VTKFile type=\"Collection\" version=\"0.1\" byte_order=\"LittleEndian\">\n  <Collection>\n",
        );
        for (t, file) in &self.frames {
            // `{t}` is the shortest text that reads back as the same f64.
            let _ = writeln!(
                s,
                "    <DataSet timestep=\"{t}\" group=\"\" part=\"0\" file=\"{file}\"/>"
            );
        }
        s.push_str("  </Collection>\n</VTKFile>\n");
        // Replaced whole (temporary file, then rename): a kill while it is rewritten
        // leaves the previous collection, never an empty or torn one.
        let path = self.pvd_path();
        crate::paths::write_atomic(&path, s.as_bytes()).map_err(|e| OutputError::io(&path, e))
    }
}

/// One array of the appended section.
enum Values {
    F64(Vec<f64>),
    I64(Vec<i64>),
    U8(Vec<u8>),
}

struct Array {
    name: &'static str,
    components: usize,
    values: Values,
}

impl Array {
    fn f64(name: &'static str, components: usize) -> Self {
        Self {
            name,
            components,
            values: Values::F64(Vec::new()),
        }
    }
    fn i64(name: &'static str, values: Vec<i64>) -> Self {
        Self {
            name,
            components: 1,
            values: Values::I64(values),
        }
    }
    fn push3(&mut self, v: &Vec3) {
        if let Values::F64(x) = &mut self.values {
            x.extend_from_slice(v.as_slice());
        }
    }
    fn type_name(&self) -> &'static str {
        match self.values {
            Values::F64(_) => "Float64",
            Values::I64(_) => "Int64",
            Values::U8(_) => "UInt8",
        }
    }
    fn bytes(&self) -> Vec<u8> {
        match &self.values {
            Values::F64(x) => x.iter().flat_map(|v| v.to_le_bytes()).collect(),
            Values::I64(x) => x.iter().flat_map(|v| v.to_le_bytes()).collect(),
            Values::U8(x) => x.clone(),
        }
    }
}

/// Writes the `DataArray` tags of `arrays` into `xml` and their data into `data`.
fn add_arrays(xml: &mut String, data: &mut Vec<u8>, arrays: &[Array]) {
    for a in arrays {
        let _ = writeln!(
            xml,
            "        <DataArray type=\"{}\" Name=\"{}\" NumberOfComponents=\"{}\" format=\"appended\" offset=\"{}\"/>",
            a.type_name(),
            a.name,
            a.components,
            data.len()
        );
        let bytes = a.bytes();
        data.extend((bytes.len() as u64).to_le_bytes());
        data.extend(bytes);
    }
}

/// The `.vtu` file of the current level of `sim`.
fn vtu_bytes(sim: &Simulation) -> Vec<u8> {
    let (model, state, data) = (sim.model(), sim.state(), sim.element_data());
    let (ends, rod_of_node) = node_director_ends(model);
    let n = model.n_nodes();
    let n_links = model.links.len();
    let n_points = n + n_links;
    let n_cells = model.elements.len() + n_links;

    let mut points = Array::f64("Points", 3);
    let mut disp = Array::f64("displacement", 3);
    let mut vel = Array::f64("velocity", 3);
    let mut d = [
        Array::f64("d1", 3),
        Array::f64("d2", 3),
        Array::f64("d3", 3),
    ];
    for a in 0..n {
        points.push3(&state.r[a]);
        disp.push3(&(state.r[a] - model.nodes[a]));
        vel.push3(&state.v[a]);
        let (e, l) = ends[a];
        for (k, dk) in d.iter_mut().enumerate() {
            if e == usize::MAX {
                dk.push3(&Vec3::zeros());
            } else {
                dk.push3(&state.d[e][l].column(k).into_owned());
            }
        }
    }
    for link in &model.links {
        points.push3(&link.pivot);
        for arr in [&mut disp, &mut vel] {
            arr.push3(&Vec3::zeros());
        }
        d.iter_mut().for_each(|dk| dk.push3(&Vec3::zeros()));
    }
    let node_id = Array::i64(
        "node_id",
        (0..n as i64)
            .chain(std::iter::repeat_n(-1, n_links))
            .collect(),
    );
    let point_rod = Array::i64(
        "rod_id",
        rod_of_node
            .iter()
            .copied()
            .chain(std::iter::repeat_n(-1, n_links))
            .collect(),
    );

    let mut gamma = Array::f64("strain_Gamma", 3);
    let mut omega = Array::f64("strain_Omega", 3);
    let mut n_res = Array::f64("N", 3);
    let mut m_res = Array::f64("M", 3);
    let mut conn: Vec<i64> = Vec::with_capacity(2 * n_cells);
    for (e, el) in model.elements.iter().enumerate() {
        conn.extend(el.nodes.map(|a| a as i64));
        let de = state.eps[e] - data[e].eps0;
        let g = de.fixed_rows::<3>(0).into_owned();
        let o = de.fixed_rows::<3>(3).into_owned();
        let p = &data[e].props;
        gamma.push3(&g);
        omega.push3(&o);
        n_res.push3(&p.c_gamma.component_mul(&g));
        m_res.push3(&(p.c_omega * o));
    }
    for (k, link) in model.links.iter().enumerate() {
        conn.extend([(n + k) as i64, link.node as i64]);
        for arr in [&mut gamma, &mut omega, &mut n_res, &mut m_res] {
            arr.push3(&Vec3::zeros());
        }
    }
    let element_id = Array::i64(
        "element_id",
        (0..model.elements.len() as i64)
            .chain(std::iter::repeat_n(-1, n_links))
            .collect(),
    );
    let cell_rod = Array::i64(
        "rod_id",
        model
            .elements
            .iter()
            .map(|el| el.rod as i64)
            .chain(std::iter::repeat_n(-1, n_links))
            .collect(),
    );
    let link_flag = Array {
        name: "link",
        components: 1,
        values: Values::U8(
            std::iter::repeat_n(0u8, model.elements.len())
                .chain(std::iter::repeat_n(1u8, n_links))
                .collect(),
        ),
    };
    let offsets = Array::i64("offsets", (1..=n_cells as i64).map(|i| 2 * i).collect());
    // VTK_LINE = 3.
    let types = Array {
        name: "types",
        components: 1,
        values: Values::U8(vec![3; n_cells]),
    };

    let mut xml = String::new();
    let mut bin: Vec<u8> = Vec::new();
    xml.push_str("<?xml version=\"1.0\"?>\n<VTKFile type=\"UnstructuredGrid\" version=\"1.0\" byte_order=\"LittleEndian\" header_type=\"UInt64\">\n  <UnstructuredGrid>\n");
    let _ = writeln!(
        xml,
        "    <Piece NumberOfPoints=\"{n_points}\" NumberOfCells=\"{n_cells}\">"
    );
    xml.push_str("      <Points>\n");
    add_arrays(&mut xml, &mut bin, &[points]);
    xml.push_str("      </Points>\n      <PointData Vectors=\"velocity\">\n");
    let [d1, d2, d3] = d;
    add_arrays(
        &mut xml,
        &mut bin,
        &[node_id, point_rod, disp, vel, d1, d2, d3],
    );
    xml.push_str("      </PointData>\n      <CellData>\n");
    add_arrays(
        &mut xml,
        &mut bin,
        &[element_id, cell_rod, link_flag, gamma, omega, n_res, m_res],
    );
    xml.push_str("      </CellData>\n      <Cells>\n");
    add_arrays(
        &mut xml,
        &mut bin,
        &[Array::i64("connectivity", conn), offsets, types],
    );
    xml.push_str("      </Cells>\n    </Piece>\n  </UnstructuredGrid>\n  <AppendedData encoding=\"raw\">\n   _");
    let mut out = xml.into_bytes();
    out.extend(bin);
    out.extend_from_slice(b"\n  </AppendedData>\n</VTKFile>\n");
    out
}
