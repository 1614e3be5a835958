//! VTK output for ParaView: one `.vtu` (XML unstructured grid, ASCII) per saved level and a
//! `.pvd` collection that lists them with their times.
//!
//! Every element is a `VTK_LINE` cell with **its own two points** (the element ends), not
//! shared nodes: a rigid corner is one node with a different director triad on each side,
//! and per-end points let ParaView show both. Point data: velocity and the directors
//! `d1, d2, d3`; cell data: the strains `Γ − Γ0`, `Ω − Ω0` and the stress resultants
//! `N = C_Γ(Γ − Γ0)`, `M = C_Ω(Ω − Ω0)` in the director basis (the paper's convention).
//! Rigid links are written as extra line cells (pivot → node) with zero point data and a
//! `link` cell flag, so the mechanism looks like the mechanism.
//!
//! Written by hand (about a hundred lines of XML) rather than through a VTK crate: the
//! format is tiny and stable, and the crates available pull in far more than we use.

use std::fmt::Write as _;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use super::OutputError;
use crate::integrator::Simulation;
use crate::model::Vec3;

/// Writes `NAME_000042.vtu` files into a folder and `NAME.pvd` on [`finish`](Self::finish)
/// (and every [`PVD_EVERY`] frames, so an interrupted run keeps a valid collection of most
/// of its frames without rewriting the collection after every frame).
/// The collection file is rewritten after this many frames.
pub const PVD_EVERY: usize = 64;

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

    /// Writes the current level of `sim` as the next frame.
    pub fn write_frame(&mut self, sim: &Simulation, step: usize) -> Result<(), OutputError> {
        let file = format!("{}_{step:06}.vtu", self.name);
        let path = self.dir.join(&file);
        let text = vtu_text(sim);
        write_file(&path, &text)?;
        self.frames.push((sim.state().t, file));
        if self.frames.len().is_multiple_of(PVD_EVERY) {
            self.write_pvd()?;
        }
        Ok(())
    }

    /// Writes the `.pvd` collection of all frames written.
    pub fn finish(&self) -> Result<(), OutputError> {
        self.write_pvd()
    }

    /// Path of the `.pvd` collection.
    pub fn pvd_path(&self) -> PathBuf {
        self.dir.join(format!("{}.pvd", self.name))
    }

    fn write_pvd(&self) -> Result<(), OutputError> {
        let mut s = String::from(
            "<?xml version=\"1.0\"?>\n<VTKFile type=\"Collection\" version=\"0.1\" byte_order=\"LittleEndian\">\n  <Collection>\n",
        );
        for (t, file) in &self.frames {
            let _ = writeln!(
                s,
                "    <DataSet timestep=\"{t:e}\" group=\"\" part=\"0\" file=\"{file}\"/>"
            );
        }
        s.push_str("  </Collection>\n</VTKFile>\n");
        write_file(&self.pvd_path(), &s)
    }
}

fn write_file(path: &Path, text: &str) -> Result<(), OutputError> {
    let f = File::create(path).map_err(|e| OutputError::io(path, e))?;
    let mut w = BufWriter::new(f);
    w.write_all(text.as_bytes())
        .and_then(|()| w.flush())
        .map_err(|e| OutputError::io(path, e))
}

/// One data array of the XML file.
struct Array {
    name: &'static str,
    components: usize,
    values: Vec<f64>,
}

impl Array {
    fn vec3(name: &'static str) -> Self {
        Self {
            name,
            components: 3,
            values: Vec::new(),
        }
    }
    fn push(&mut self, v: &Vec3) {
        self.values.extend_from_slice(v.as_slice());
    }
    fn write(&self, s: &mut String) {
        let _ = writeln!(
            s,
            "        <DataArray type=\"Float64\" Name=\"{}\" NumberOfComponents=\"{}\" format=\"ascii\">",
            self.name, self.components
        );
        s.push_str("          ");
        for (i, v) in self.values.iter().enumerate() {
            if i > 0 {
                s.push(' ');
            }
            let _ = write!(s, "{v:e}");
        }
        s.push_str("\n        </DataArray>\n");
    }
}

/// The `.vtu` text of the current level of `sim`.
fn vtu_text(sim: &Simulation) -> String {
    let (model, state, data) = (sim.model(), sim.state(), sim.element_data());
    let mut points = Array::vec3("Points");
    let mut velocity = Array::vec3("velocity");
    let mut d = [Array::vec3("d1"), Array::vec3("d2"), Array::vec3("d3")];
    let mut gamma = Array::vec3("strain_Gamma");
    let mut omega = Array::vec3("strain_Omega");
    let mut n_res = Array::vec3("N");
    let mut m_res = Array::vec3("M");
    let mut link_flag = Array {
        name: "link",
        components: 1,
        values: Vec::new(),
    };
    for (e, el) in model.elements.iter().enumerate() {
        for l in 0..2 {
            let a = el.nodes[l];
            points.push(&state.r[a]);
            velocity.push(&state.v[a]);
            for (i, di) in d.iter_mut().enumerate() {
                di.push(&state.d[e][l].column(i).into_owned());
            }
        }
        let de = state.eps[e] - data[e].eps0;
        let g = de.fixed_rows::<3>(0).into_owned();
        let o = de.fixed_rows::<3>(3).into_owned();
        let p = &data[e].props;
        gamma.push(&g);
        omega.push(&o);
        n_res.push(&p.c_gamma.component_mul(&g));
        m_res.push(&(p.c_omega * o));
        link_flag.values.push(0.0);
    }
    for link in &model.links {
        points.push(&link.pivot);
        points.push(&state.r[link.node]);
        for _ in 0..2 {
            velocity.push(&Vec3::zeros());
            d.iter_mut().for_each(|di| di.push(&Vec3::zeros()));
        }
        for arr in [&mut gamma, &mut omega, &mut n_res, &mut m_res] {
            arr.push(&Vec3::zeros());
        }
        link_flag.values.push(1.0);
    }
    let n_cells = model.elements.len() + model.links.len();
    let mut s = String::new();
    s.push_str("<?xml version=\"1.0\"?>\n<VTKFile type=\"UnstructuredGrid\" version=\"0.1\" byte_order=\"LittleEndian\">\n  <UnstructuredGrid>\n");
    let _ = writeln!(
        s,
        "    <Piece NumberOfPoints=\"{}\" NumberOfCells=\"{n_cells}\">",
        2 * n_cells
    );
    s.push_str("      <Points>\n");
    points.write(&mut s);
    s.push_str("      </Points>\n      <PointData Vectors=\"velocity\">\n");
    velocity.write(&mut s);
    d.iter().for_each(|a| a.write(&mut s));
    s.push_str("      </PointData>\n      <CellData>\n");
    for a in [&gamma, &omega, &n_res, &m_res, &link_flag] {
        a.write(&mut s);
    }
    s.push_str("      </CellData>\n      <Cells>\n");
    s.push_str(
        "        <DataArray type=\"Int64\" Name=\"connectivity\" format=\"ascii\">\n          ",
    );
    let conn: Vec<String> = (0..2 * n_cells).map(|i| i.to_string()).collect();
    s.push_str(&conn.join(" "));
    s.push_str("\n        </DataArray>\n        <DataArray type=\"Int64\" Name=\"offsets\" format=\"ascii\">\n          ");
    let offs: Vec<String> = (1..=n_cells).map(|i| (2 * i).to_string()).collect();
    s.push_str(&offs.join(" "));
    s.push_str("\n        </DataArray>\n        <DataArray type=\"UInt8\" Name=\"types\" format=\"ascii\">\n          ");
    // VTK_LINE = 3.
    let types: Vec<&str> = (0..n_cells).map(|_| "3").collect();
    s.push_str(&types.join(" "));
    s.push_str(
        "\n        </DataArray>\n      </Cells>\n    </Piece>\n  </UnstructuredGrid>\n</VTKFile>\n",
    );
    s
}
