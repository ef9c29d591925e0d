// SPDX-License-Identifier: MIT
#pragma once
// Private HDF5 helpers of aneu_core: typed dataset/attribute I/O with shape checks and error messages
// that name the file, the object and what was expected. Not installed, not included outside core/.
#include <cstdint>
#include <string>
#include <vector>

#include <H5Cpp.h>

namespace aneu::h5 {

/// Identifies what is being read, for messages: "<file>: <object>".
struct Ctx {
    std::string file;
    std::string where(const std::string& obj) const { return file + ": " + obj; }
};

template <class T> const H5::PredType& pred();
template <> inline const H5::PredType& pred<double>() { return H5::PredType::NATIVE_DOUBLE; }
template <> inline const H5::PredType& pred<float>() { return H5::PredType::NATIVE_FLOAT; }
template <> inline const H5::PredType& pred<std::int32_t>() { return H5::PredType::NATIVE_INT32; }
template <> inline const H5::PredType& pred<std::int64_t>() { return H5::PredType::NATIVE_INT64; }
template <> inline const H5::PredType& pred<std::uint8_t>() { return H5::PredType::NATIVE_UINT8; }

/// The innermost message of the current HDF5 error stack (what the library actually complained about).
std::string last_error_detail();
/// Disables HDF5's automatic printing of errors to stderr (we report them ourselves). Idempotent.
void silence_hdf5();

/// Opens an existing bundle for reading and checks the format marker and schema version.
/// @throws InputError naming the file: missing, a directory, not HDF5, truncated/corrupt, not a bundle, other
///         schema version (the file is the user's input; exit code 2)
H5::H5File open_bundle(const std::string& path);

bool exists(const H5::Group& g, const std::string& name);

// ---- writing ----
/// Writes an N-d dataset (row-major dims). Chunked + shuffle + deflate when it has ≥ 4096 elements and
/// deflate_level > 0. Writes a `units` attribute when units is non-empty.
template <class T>
void write_array(H5::Group& g, const std::string& name, const T* data, const std::vector<hsize_t>& dims,
                 const std::string& units = "", int deflate_level = 4);
void write_strings(H5::Group& g, const std::string& name, const std::vector<std::string>& s);
void write_attr(H5::H5Object& o, const std::string& name, const std::string& v);
void write_attr(H5::H5Object& o, const std::string& name, double v);
void write_attr(H5::H5Object& o, const std::string& name, std::int64_t v);

// ---- reading (every function checks presence, type class and shape) ----
/// Reads a dataset of rank dims_expected.size(); an expected dim < 0 matches any extent, and the actual
/// extents are returned in dims. `shape_doc` is how the expected shape reads in messages, e.g. "[T,4]".
template <class T>
std::vector<T> read_array(const H5::Group& g, const std::string& path_in_file, const std::string& name,
                          const std::vector<long long>& dims_expected, std::vector<hsize_t>& dims,
                          const Ctx& ctx, const std::string& shape_doc);
std::vector<std::string> read_strings(const H5::Group& g, const std::string& path_in_file,
                                      const std::string& name, const Ctx& ctx);
std::string read_attr_string(const H5::H5Object& o, const std::string& obj_path, const std::string& name,
                             const Ctx& ctx);
double read_attr_double(const H5::H5Object& o, const std::string& obj_path, const std::string& name,
                        const Ctx& ctx);
std::int64_t read_attr_int(const H5::H5Object& o, const std::string& obj_path, const std::string& name,
                           const Ctx& ctx);
/// Names of all attributes of o, in creation/name order.
std::vector<std::string> attr_names(const H5::H5Object& o);
/// Names of the links (children) of a group, sorted by name.
std::vector<std::string> child_names(const H5::Group& g);

std::string shape_string(const std::vector<hsize_t>& dims);

}  // namespace aneu::h5
