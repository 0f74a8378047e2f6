//! Checkpoint and restart: the complete committed state of a run (every particle column, the rigid bodies,
//! the counters) and what its output has recorded so far, in one HDF5 file `checkpoint.h5` written
//! atomically at every output step and when a run is interrupted. A resumed run continues bit for bit: the
//! step is deterministic (assembly by gather, ordered reductions), so it ends with the same results as an
//! uninterrupted one.

use crate::io::{OutputError, RunOutput};
use crate::solver::{Counters, Method, Simulation};
use nalgebra::{Matrix2, Matrix3, Vector2};
use std::path::Path;

/// File name of the checkpoint inside the output directory.
pub const FILE: &str = "checkpoint.h5";

fn h5_err(path: &Path) -> impl Fn(hdf5_metno::Error) -> OutputError + '_ {
    move |e| OutputError::Hdf5 {
        path: path.display().to_string(),
        message: e.to_string(),
    }
}

fn flat2(v: &[Vector2<f64>]) -> Vec<f64> {
    v.iter().flat_map(|x| [x.x, x.y]).collect()
}

fn unflat2(f: &[f64]) -> Vec<Vector2<f64>> {
    f.chunks_exact(2)
        .map(|c| Vector2::new(c[0], c[1]))
        .collect()
}

/// Writes the state of `sim` and the records of `out` to `dir/checkpoint.h5`.
pub fn save(dir: &Path, sim: &Simulation, out: &RunOutput) -> Result<(), OutputError> {
    let path = dir.join(FILE);
    let tmp = dir.join(format!("{FILE}.tmp"));
    write(&tmp, sim, out).map_err(h5_err(&path))?;
    std::fs::rename(&tmp, &path).map_err(|source| OutputError::Io {
        path: path.display().to_string(),
        source,
    })
}

fn write(path: &Path, sim: &Simulation, out: &RunOutput) -> hdf5_metno::Result<()> {
    let f = hdf5_metno::File::create(path)?;
    let p = &sim.setup.particles;
    let put = |name: &str, data: &[f64]| {
        f.new_dataset_builder()
            .with_data(data)
            .create(name)
            .map(|_| ())
    };
    put("x", &flat2(&p.x))?;
    put("v", &flat2(&p.v))?;
    put("a", &flat2(&p.a))?;
    put("r1", &flat2(&p.r1))?;
    put("r2", &flat2(&p.r2))?;
    put("vol", &p.vol)?;
    put(
        "f",
        &p.f.iter()
            .flat_map(|m| m.iter().copied().collect::<Vec<_>>())
            .collect::<Vec<_>>(),
    )?;
    put(
        "stress",
        &p.stress
            .iter()
            .flat_map(|m| m.iter().copied().collect::<Vec<_>>())
            .collect::<Vec<_>>(),
    )?;
    put(
        "corners",
        &p.corners.iter().flat_map(|c| flat2(c)).collect::<Vec<_>>(),
    )?;
    put("history", &p.history)?;
    put("eta_bar", &p.eta_bar)?;
    put("damage", &p.damage)?;
    for (k, rb) in sim.setup.rigid.iter().enumerate() {
        put(&format!("rigid{k}_x"), &flat2(&rb.particles.x))?;
        put(
            &format!("rigid{k}_corners"),
            &rb.particles
                .corners
                .iter()
                .flat_map(|c| flat2(c))
                .collect::<Vec<_>>(),
        )?;
    }
    if let Some((v, a)) = sim.fem_nodal_state() {
        put("fem_nodal_velocity", &flat2(v))?;
        put("fem_nodal_acceleration", &flat2(a))?;
    }
    let counters = serde_json::to_value(sim.counters())
        .map_err(|e| hdf5_metno::Error::from(e.to_string().as_str()))?;
    let text = serde_json::json!({
        "counters": counters,
        "records": out.records_json(),
        "points": p.len(),
        "history_stride": p.history_stride(),
    })
    .to_string();
    f.new_dataset_builder()
        .with_data(text.as_bytes())
        .create("meta")?;
    Ok(())
}

/// Restores `sim` (freshly built from the same configuration) and `out` from `dir/checkpoint.h5`.
pub fn load(dir: &Path, sim: &mut Simulation, out: &mut RunOutput) -> Result<(), OutputError> {
    let path = dir.join(FILE);
    read(&path, sim, out).map_err(h5_err(&path))
}

fn read(path: &Path, sim: &mut Simulation, out: &mut RunOutput) -> hdf5_metno::Result<()> {
    let f = hdf5_metno::File::open(path)?;
    let meta_bytes: Vec<u8> = f.dataset("meta")?.read_raw()?;
    let meta: serde_json::Value = serde_json::from_slice(&meta_bytes)
        .map_err(|e| hdf5_metno::Error::from(format!("meta: {e}").as_str()))?;
    let p = &mut sim.setup.particles;
    let n = p.len();
    let bad = |what: &str| hdf5_metno::Error::from(what);
    if meta["points"].as_u64() != Some(n as u64) {
        return Err(bad(
            "the checkpoint has a different number of material points than the configuration",
        ));
    }
    let get = |name: &str, len: usize| -> hdf5_metno::Result<Vec<f64>> {
        let v: Vec<f64> = f.dataset(name)?.read_raw()?;
        if v.len() != len {
            return Err(hdf5_metno::Error::from(
                format!("dataset {name}: {} values, expected {len}", v.len()).as_str(),
            ));
        }
        Ok(v)
    };
    p.x = unflat2(&get("x", 2 * n)?);
    p.v = unflat2(&get("v", 2 * n)?);
    p.a = unflat2(&get("a", 2 * n)?);
    p.r1 = unflat2(&get("r1", 2 * n)?);
    p.r2 = unflat2(&get("r2", 2 * n)?);
    p.vol = get("vol", n)?;
    p.f = get("f", 4 * n)?
        .chunks_exact(4)
        .map(Matrix2::from_column_slice)
        .collect();
    p.stress = get("stress", 9 * n)?
        .chunks_exact(9)
        .map(Matrix3::from_column_slice)
        .collect();
    p.corners = get("corners", 8 * n)?
        .chunks_exact(8)
        .map(|c| {
            let v = unflat2(c);
            [v[0], v[1], v[2], v[3]]
        })
        .collect();
    let stride = meta["history_stride"].as_u64().unwrap_or(0) as usize;
    if stride != p.history_stride() {
        return Err(bad(
            "the checkpoint's material history has a different layout than the configuration",
        ));
    }
    p.history = get("history", n * stride)?;
    p.eta_bar = get("eta_bar", n)?;
    p.damage = get("damage", n)?;
    for (k, rb) in sim.setup.rigid.iter_mut().enumerate() {
        let m = rb.particles.len();
        rb.particles.x = unflat2(&get(&format!("rigid{k}_x"), 2 * m)?);
        rb.particles.corners = get(&format!("rigid{k}_corners"), 8 * m)?
            .chunks_exact(8)
            .map(|c| {
                let v = unflat2(c);
                [v[0], v[1], v[2], v[3]]
            })
            .collect();
    }
    if sim.setup.method == Method::Fem && f.link_exists("fem_nodal_velocity") {
        let nodes = sim.setup.grid.num_nodes();
        sim.set_fem_nodal_state(
            unflat2(&get("fem_nodal_velocity", 2 * nodes)?),
            unflat2(&get("fem_nodal_acceleration", 2 * nodes)?),
        );
    }
    let counters: Counters = serde_json::from_value(meta["counters"].clone())
        .map_err(|e| bad(&format!("counters: {e}")))?;
    sim.set_counters(counters);
    out.restore_records(&meta["records"])
        .map_err(|e| bad(&format!("records: {e}")))?;
    Ok(())
}
