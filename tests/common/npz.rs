//! `.npz` files opened, edited and forged in tests: every array by name, one array rewritten,
//! one entry replaced by hand-made `.npy` bytes.

use std::fs;
use std::path::Path;

use ndarray::{ArrayD, IxDyn};
use ndarray_npy::{NpzReader, NpzWriter};

/// Every array of an `.npz`, as i64 or f64 arrays by name.
pub enum Npy {
    I(ArrayD<i64>),
    F(ArrayD<f64>),
    U(ArrayD<u8>),
}

pub fn read_npz(path: &Path) -> Vec<(String, Npy)> {
    let mut z = NpzReader::new(fs::File::open(path).unwrap()).unwrap();
    let names = z.names().unwrap();
    names
        .into_iter()
        .map(|n| {
            let name = n.trim_end_matches(".npy").to_string();
            let a = match z.by_name::<ndarray::OwnedRepr<i64>, IxDyn>(&name) {
                Ok(a) => Npy::I(a),
                Err(_) => match z.by_name::<ndarray::OwnedRepr<u8>, IxDyn>(&name) {
                    Ok(a) => Npy::U(a),
                    Err(_) => Npy::F(z.by_name::<ndarray::OwnedRepr<f64>, IxDyn>(&name).unwrap()),
                },
            };
            (name, a)
        })
        .collect()
}

pub fn write_npz(path: &Path, arrays: &[(String, Npy)]) {
    let mut z = NpzWriter::new_compressed(fs::File::create(path).unwrap());
    for (name, a) in arrays {
        match a {
            Npy::I(a) => z.add_array(name.as_str(), a).unwrap(),
            Npy::F(a) => z.add_array(name.as_str(), a).unwrap(),
            Npy::U(a) => z.add_array(name.as_str(), a).unwrap(),
        }
    }
    z.finish().unwrap();
}

/// Rewrites one array of an `.npz` file.
pub fn edit_npz(path: &Path, name: &str, edit: impl FnOnce(&mut Npy)) {
    let mut arrays = read_npz(path);
    edit(&mut arrays.iter_mut().find(|(n, _)| n == name).unwrap_or_else(|| panic!("no array {name}")).1);
    write_npz(path, &arrays);
}

/// An `.npy` whose header declares `shape` of `descr` (e.g. `<f8`), followed by `data` bytes only.
pub fn npy(descr: &str, shape: &[u64], data: &[u8]) -> Vec<u8> {
    let dims: Vec<String> = shape.iter().map(|d| format!("{d},")).collect();
    let mut dict = format!("{{'descr': '{descr}', 'fortran_order': False, 'shape': ({}), }}", dims.join(" "));
    while (10 + dict.len() + 1) % 64 != 0 {
        dict.push(' ');
    }
    dict.push('\n');
    let mut v = b"\x93NUMPY\x01\x00".to_vec();
    v.extend((dict.len() as u16).to_le_bytes());
    v.extend(dict.as_bytes());
    v.extend(data);
    v
}

/// Rewrites the `.npz` at `path` with the entry `name.npy` replaced by `bytes`.
pub fn replace_npz_entry(path: &Path, name: &str, bytes: &[u8]) {
    use std::io::{Read, Write};
    let mut zip = zip::ZipArchive::new(fs::File::open(path).unwrap()).unwrap();
    let mut entries = Vec::new();
    for i in 0..zip.len() {
        let mut e = zip.by_index(i).unwrap();
        let mut data = Vec::new();
        e.read_to_end(&mut data).unwrap();
        entries.push((e.name().to_string(), data));
    }
    let mut w = zip::ZipWriter::new(fs::File::create(path).unwrap());
    let options = zip::write::SimpleFileOptions::default().compression_method(zip::CompressionMethod::Deflated);
    for (n, data) in entries {
        w.start_file(n.as_str(), options).unwrap();
        w.write_all(if n == format!("{name}.npy") { bytes } else { &data }).unwrap();
    }
    w.finish().unwrap();
}
