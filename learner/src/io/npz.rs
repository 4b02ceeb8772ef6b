//! `.npz` files (numpy's `np.savez` layout: a zip of `.npy` arrays) for everything that leaves
//! the program: demonstrations, recorded episodes, gain tables (docs/design.md §4.1).
//!
//! Writing goes to `<path>.partial`, which [`NpzWriter::finish`] syncs to disk and renames into
//! place ([`ur5_shared::atomic_file::commit`]), so a crash never leaves a truncated file under
//! the final name. Arrays are little-endian, C order.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufWriter, Read, Write};
use std::path::{Path, PathBuf};

use npyz::WriterBuilder;
use zip::write::SimpleFileOptions;
use zip::{CompressionMethod, ZipArchive, ZipWriter};

/// Errors reading or writing `.npz` files; each names the file and, where it applies, the array.
#[derive(Debug, thiserror::Error)]
pub enum NpzError {
    /// File system error.
    #[error("{path}: {source}")]
    Io {
        /// File concerned.
        path: PathBuf,
        /// Underlying error.
        source: std::io::Error,
    },
    /// Not a zip archive, or a damaged one.
    #[error("{path}: not a readable .npz archive: {message}")]
    Zip {
        /// File concerned.
        path: PathBuf,
        /// What the zip reader said.
        message: String,
    },
    /// A required array is absent.
    #[error("{path}: no array `{name}` (arrays present: {present:?})")]
    Missing {
        /// File concerned.
        path: PathBuf,
        /// Array asked for.
        name: String,
        /// Arrays the file has.
        present: Vec<String>,
    },
    /// An array has the wrong element type or shape, or bad values.
    #[error("{path}: array `{name}`: {why}")]
    Bad {
        /// File concerned.
        path: PathBuf,
        /// Array concerned.
        name: String,
        /// What is wrong.
        why: String,
    },
}

/// Writes a `.npz` file array by array.
pub struct NpzWriter {
    zip: ZipWriter<BufWriter<File>>,
    partial: PathBuf,
    path: PathBuf,
}

impl NpzWriter {
    /// Starts writing `path` (through `path.partial`).
    pub fn create(path: &Path) -> Result<Self, NpzError> {
        let mut partial = path.as_os_str().to_owned();
        partial.push(".partial");
        let partial = PathBuf::from(partial);
        let io = |source| NpzError::Io {
            path: partial.clone(),
            source,
        };
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).map_err(io)?;
        }
        let file = File::create(&partial).map_err(io)?;
        Ok(Self {
            zip: ZipWriter::new(BufWriter::new(file)),
            partial,
            path: path.to_owned(),
        })
    }

    fn start(&mut self, name: &str) -> Result<(), NpzError> {
        let opts = SimpleFileOptions::default()
            .compression_method(CompressionMethod::Stored)
            .large_file(true);
        self.zip
            .start_file(format!("{name}.npy"), opts)
            .map_err(|e| NpzError::Zip {
                path: self.partial.clone(),
                message: e.to_string(),
            })
    }

    fn io(&self) -> impl Fn(std::io::Error) -> NpzError + '_ {
        move |source| NpzError::Io {
            path: self.partial.clone(),
            source,
        }
    }

    /// Adds a float64 array of `shape` (C order); `data.len()` must equal the product of `shape`.
    pub fn f64(&mut self, name: &str, shape: &[u64], data: &[f64]) -> Result<(), NpzError> {
        self.numeric(name, shape, data)
    }

    /// Adds an int64 array.
    pub fn i64(&mut self, name: &str, shape: &[u64], data: &[i64]) -> Result<(), NpzError> {
        self.numeric(name, shape, data)
    }

    /// Adds a uint64 array.
    pub fn u64(&mut self, name: &str, shape: &[u64], data: &[u64]) -> Result<(), NpzError> {
        self.numeric(name, shape, data)
    }

    fn numeric<T: npyz::AutoSerialize + Copy>(
        &mut self,
        name: &str,
        shape: &[u64],
        data: &[T],
    ) -> Result<(), NpzError> {
        let n: u64 = shape.iter().product();
        assert_eq!(
            n as usize,
            data.len(),
            "array `{name}`: shape {shape:?} does not match {} values",
            data.len()
        );
        self.start(name)?;
        let mut buf = Vec::with_capacity(128 + std::mem::size_of_val(data));
        {
            let mut w = npyz::WriteOptions::new()
                .default_dtype()
                .shape(shape)
                .writer(&mut buf)
                .begin_nd()
                .map_err(self.io())?;
            w.extend(data.iter().copied()).map_err(self.io())?;
            w.finish().map_err(self.io())?;
        }
        self.zip.write_all(&buf).map_err(self.io())
    }

    /// Adds a 1-D array of unicode strings (numpy dtype `<U{max len}`).
    pub fn strings(&mut self, name: &str, values: &[&str]) -> Result<(), NpzError> {
        let width = values
            .iter()
            .map(|s| s.chars().count())
            .max()
            .unwrap_or(1)
            .max(1);
        let dtype = npyz::DType::Plain(
            format!("<U{width}")
                .parse::<npyz::TypeStr>()
                .expect("valid type string"),
        );
        self.start(name)?;
        let mut buf = Vec::new();
        {
            let mut w = npyz::WriteOptions::<str>::new()
                .dtype(dtype)
                .shape(&[values.len() as u64])
                .writer(&mut buf)
                .begin_nd()
                .map_err(self.io())?;
            for v in values {
                w.push(*v).map_err(self.io())?;
            }
            w.finish().map_err(self.io())?;
        }
        self.zip.write_all(&buf).map_err(self.io())
    }

    /// Adds a 0-d string (numpy `<U`), e.g. a JSON document of metadata.
    pub fn string(&mut self, name: &str, value: &str) -> Result<(), NpzError> {
        self.strings(name, &[value])
    }

    /// Finishes the archive, flushes it to disk and moves it to its final name.
    pub fn finish(self) -> Result<PathBuf, NpzError> {
        let partial = self.partial.clone();
        let writer = self.zip.finish().map_err(|e| NpzError::Zip {
            path: partial.clone(),
            message: e.to_string(),
        })?;
        let file = writer.into_inner().map_err(|e| NpzError::Io {
            path: partial.clone(),
            source: e.into_error(),
        })?;
        file.sync_all().map_err(|source| NpzError::Io {
            path: partial.clone(),
            source,
        })?;
        ur5_shared::atomic_file::commit(&partial, &self.path).map_err(|source| NpzError::Io {
            path: self.path.clone(),
            source,
        })?;
        Ok(self.path)
    }
}

/// One array read from a `.npz` file.
#[derive(Clone, Debug)]
struct RawArray {
    bytes: Vec<u8>,
}

/// A `.npz` file read into memory.
pub struct NpzFile {
    path: PathBuf,
    arrays: BTreeMap<String, RawArray>,
}

impl NpzFile {
    /// Reads every array of `path`.
    pub fn open(path: &Path) -> Result<Self, NpzError> {
        let file = File::open(path).map_err(|source| NpzError::Io {
            path: path.to_owned(),
            source,
        })?;
        let file_len = file.metadata().map(|m| m.len()).unwrap_or(0);
        Self::read_from(path, file, file_len)
    }

    /// Reads every array of an `.npz` file held in memory (`bytes`; `path` names it in
    /// errors), e.g. one built into the program.
    pub fn from_bytes(path: &Path, bytes: &[u8]) -> Result<Self, NpzError> {
        Self::read_from(path, std::io::Cursor::new(bytes), bytes.len() as u64)
    }

    fn read_from<R: Read + std::io::Seek>(
        path: &Path,
        file: R,
        file_len: u64,
    ) -> Result<Self, NpzError> {
        let zerr = |e: zip::result::ZipError| NpzError::Zip {
            path: path.to_owned(),
            message: e.to_string(),
        };
        let mut zip = ZipArchive::new(file).map_err(zerr)?;
        let mut arrays = BTreeMap::new();
        for i in 0..zip.len() {
            let mut entry = zip.by_index(i).map_err(zerr)?;
            let entry_name = entry.name().map_err(|e| NpzError::Zip {
                path: path.to_owned(),
                message: e.to_string(),
            })?;
            let Some(name) = entry_name.strip_suffix(".npy").map(str::to_owned) else {
                continue;
            };
            // The size in the zip header is the file's word: never reserve more than the file
            // holds (a damaged header asked for 26 TB; found by tests/tests/suite/fuzz.rs).
            let mut bytes = Vec::with_capacity(entry.size().min(file_len) as usize);
            entry
                .read_to_end(&mut bytes)
                .map_err(|source| NpzError::Io {
                    path: path.to_owned(),
                    source,
                })?;
            arrays.insert(name, RawArray { bytes });
        }
        Ok(Self {
            path: path.to_owned(),
            arrays,
        })
    }

    /// Path the file was read from.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Names of the arrays in the file.
    pub fn names(&self) -> Vec<String> {
        self.arrays.keys().cloned().collect()
    }

    fn npy(&self, name: &str) -> Result<npyz::NpyFile<&[u8]>, NpzError> {
        let raw = self.arrays.get(name).ok_or_else(|| NpzError::Missing {
            path: self.path.clone(),
            name: name.into(),
            present: self.names(),
        })?;
        npyz::NpyFile::new(&raw.bytes[..])
            .map_err(|e| self.bad(name, format!("not a valid .npy array: {e}")))
    }

    /// The error for array `name` of this file: `why` it is not what the reader needs.
    pub fn bad(&self, name: &str, why: String) -> NpzError {
        NpzError::Bad {
            path: self.path.clone(),
            name: name.into(),
            why,
        }
    }

    /// A float64 array: (shape, values in C order). Float32 and integer arrays are converted.
    pub fn f64(&self, name: &str) -> Result<(Vec<u64>, Vec<f64>), NpzError> {
        let npy = self.npy(name)?;
        let shape = npy.shape().to_vec();
        if npy.order() != npyz::Order::C {
            return Err(self.bad(
                name,
                "Fortran-ordered arrays are not supported; save with C order".into(),
            ));
        }
        let dtype = npy.dtype().descr();
        let values = match dtype.trim_matches('\'').trim_start_matches(['<', '|', '=']) {
            "f8" => npy.into_vec::<f64>(),
            "f4" => npy
                .into_vec::<f32>()
                .map(|v| v.into_iter().map(f64::from).collect()),
            "i8" => npy
                .into_vec::<i64>()
                .map(|v| v.into_iter().map(|x| x as f64).collect()),
            "i4" => npy
                .into_vec::<i32>()
                .map(|v| v.into_iter().map(f64::from).collect()),
            "u8" => npy
                .into_vec::<u64>()
                .map(|v| v.into_iter().map(|x| x as f64).collect()),
            other => {
                return Err(self.bad(
                    name,
                    format!("dtype {other} is not a little-endian float or integer"),
                ))
            }
        }
        .map_err(|e| self.bad(name, e.to_string()))?;
        Ok((shape, values))
    }

    /// The element type of array `name` as numpy spells it without the byte order (`f8`, `u8`,
    /// `i8`, `U12`, ...).
    pub fn dtype(&self, name: &str) -> Result<String, NpzError> {
        let npy = self.npy(name)?;
        Ok(npy
            .dtype()
            .descr()
            .trim_matches('\'')
            .trim_start_matches(['<', '|', '='])
            .to_owned())
    }

    /// A uint64 array, read exactly: (shape, values in C order). Other element types are an
    /// error.
    pub fn u64s(&self, name: &str) -> Result<(Vec<u64>, Vec<u64>), NpzError> {
        let dtype = self.dtype(name)?;
        if dtype != "u8" {
            return Err(self.bad(
                name,
                format!("dtype {dtype}, expected little-endian uint64"),
            ));
        }
        let npy = self.npy(name)?;
        let shape = npy.shape().to_vec();
        let v = npy
            .into_vec::<u64>()
            .map_err(|e| self.bad(name, e.to_string()))?;
        Ok((shape, v))
    }

    /// A scalar (0-d) uint64, read exactly (seeds).
    pub fn u64_scalar(&self, name: &str) -> Result<u64, NpzError> {
        let npy = self.npy(name)?;
        if !npy.shape().is_empty() {
            return Err(self.bad(name, format!("shape {:?}, expected a scalar", npy.shape())));
        }
        let v = npy
            .into_vec::<u64>()
            .map_err(|e| self.bad(name, e.to_string()))?;
        Ok(v[0])
    }

    /// A scalar uint64 that must fit a u32 (table epochs), 0 when the array is absent (files
    /// written before it was added, or written without it because it was 0).
    pub fn u32_scalar_or_zero(&self, name: &str) -> Result<u32, NpzError> {
        if !self.arrays.contains_key(name) {
            return Ok(0);
        }
        let v = self.u64_scalar(name)?;
        u32::try_from(v).map_err(|_| self.bad(name, format!("{v} is over u32::MAX")))
    }

    /// Opens `path` and checks that it is of layout version `schema` (its `schema_version`):
    /// the one preamble of every project file reader.
    pub fn open_schema(path: &Path, schema: i64) -> Result<Self, NpzError> {
        let f = Self::open(path)?;
        f.check_schema(schema)?;
        Ok(f)
    }

    /// Checks the scalar `schema_version` array against the version this program reads.
    pub fn check_schema(&self, expected: i64) -> Result<(), NpzError> {
        let version = self.f64_shaped("schema_version", &[])?[0];
        if version != expected as f64 {
            return Err(self.bad(
                "schema_version",
                format!("{version}, this program reads {expected}"),
            ));
        }
        Ok(())
    }

    /// A float64 array that must have exactly `shape`.
    pub fn f64_shaped(&self, name: &str, shape: &[u64]) -> Result<Vec<f64>, NpzError> {
        let (s, v) = self.f64(name)?;
        if s != shape {
            return Err(self.bad(name, format!("shape {s:?}, expected {shape:?}")));
        }
        Ok(v)
    }

    /// A unicode string array (numpy `<U`), as Rust strings.
    pub fn strings(&self, name: &str) -> Result<Vec<String>, NpzError> {
        let npy = self.npy(name)?;
        npy.into_vec::<String>()
            .map_err(|e| self.bad(name, e.to_string()))
    }

    /// The single string of a one-element string array.
    pub fn string(&self, name: &str) -> Result<String, NpzError> {
        let mut v = self.strings(name)?;
        if v.len() != 1 {
            return Err(self.bad(name, format!("expected one string, found {}", v.len())));
        }
        Ok(v.remove(0))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_and_clear_errors() {
        let dir = std::env::temp_dir().join(format!("npz-test-{}", std::process::id()));
        let path = dir.join("a.npz");
        let mut w = NpzWriter::create(&path).unwrap();
        let x: Vec<f64> = (0..24).map(|i| i as f64 * 0.5 - 3.0).collect();
        w.f64("x", &[2, 3, 4], &x).unwrap();
        w.i64("n", &[], &[7]).unwrap();
        w.strings("names", &["q1", "ee_minus_goal_x"]).unwrap();
        w.string("meta", "{\"dt\": 0.1}").unwrap();
        assert!(!path.exists(), "nothing under the final name before finish");
        w.finish().unwrap();
        let f = NpzFile::open(&path).unwrap();
        let (shape, back) = f.f64("x").unwrap();
        assert_eq!(shape, vec![2, 3, 4]);
        assert_eq!(back, x);
        assert_eq!(f.f64("n").unwrap(), (vec![], vec![7.0]));
        assert_eq!(f.strings("names").unwrap(), vec!["q1", "ee_minus_goal_x"]);
        assert_eq!(f.string("meta").unwrap(), "{\"dt\": 0.1}");
        let e = f.f64("y").unwrap_err().to_string();
        assert!(e.contains("no array `y`") && e.contains("\"x\""), "{e}");
        let e = f.f64_shaped("x", &[2, 3, 5]).unwrap_err().to_string();
        assert!(e.contains("shape [2, 3, 4], expected [2, 3, 5]"), "{e}");
        std::fs::write(dir.join("junk.npz"), b"not a zip").unwrap();
        assert!(matches!(
            NpzFile::open(&dir.join("junk.npz")),
            Err(NpzError::Zip { .. })
        ));
        std::fs::remove_dir_all(&dir).ok();
    }
}
