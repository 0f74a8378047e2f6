//! HDF5 through hdf5-metno, linked against Debian's openmpi HDF5 (the one PETSc uses): write datasets and
//! attributes, read them back bit for bit.

#[test]
fn write_and_read_back() {
    let dir = std::env::temp_dir().join(format!("mpmc-h5-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let path = dir.join("roundtrip.h5");
    let positions: Vec<f64> = (0..600).map(|i| (i as f64).sqrt() * 0.25).collect();
    let ids: Vec<u32> = (0..300).collect();
    {
        let file = hdf5_metno::File::create(&path).expect("create");
        let g = file.create_group("step_000001").expect("group");
        g.new_dataset_builder()
            .with_data(
                &ndarray::Array2::from_shape_vec((300, 2), positions.clone()).expect("shape"),
            )
            .create("position")
            .expect("dataset");
        g.new_dataset_builder()
            .with_data(&ids)
            .create("id")
            .expect("dataset");
        g.new_attr::<f64>()
            .create("time")
            .expect("attr")
            .write_scalar(&1.5e-6)
            .expect("write attr");
    }
    let file = hdf5_metno::File::open(&path).expect("open");
    let g = file.group("step_000001").expect("group");
    let pos = g.dataset("position").expect("dataset");
    assert_eq!(pos.shape(), vec![300, 2]);
    let back: Vec<f64> = pos.read_raw().expect("read");
    assert_eq!(back, positions);
    let back_ids: Vec<u32> = g.dataset("id").expect("dataset").read_raw().expect("read");
    assert_eq!(back_ids, ids);
    let t: f64 = g.attr("time").expect("attr").read_scalar().expect("read");
    assert_eq!(t, 1.5e-6);
    std::fs::remove_dir_all(&dir).ok();
}
