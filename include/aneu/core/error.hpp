// SPDX-License-Identifier: MIT
#pragma once
/// @file
/// The one exception hierarchy that crosses layer boundaries (CONVENTIONS.md §3).
#include <stdexcept>
#include <string>

namespace aneu {

/// Base of every aneuclip error. The message says what failed, on which object, the values involved and
/// what was expected.
class Error : public std::runtime_error {
public:
    using std::runtime_error::runtime_error;
};
/// Bad data or parameters given by the user (exit code 2).
class InputError : public Error {
public:
    using Error::Error;
};
/// An option the stage does not have (a misspelt config key or --set): exit code 109, the code CLI11 gives an
/// unknown command-line option, so a config and a command line that name the same wrong key fail alike.
class UnknownOptionError : public InputError {
public:
    using InputError::InputError;
};
/// The system failed an I/O operation on a file aneuclip reads or writes (a full disk, a failed rename, an
/// HDF5 write error): exit code 1. A user's input that is missing, unreadable or malformed is an InputError
/// (exit code 2) — the file readers (h5 open_bundle, image and mesh readers) throw that.
class IoError : public Error {
public:
    using Error::Error;
};
/// A mesher failed or produced an unusable mesh.
class MeshingError : public Error {
public:
    using Error::Error;
};
/// A numerical method failed (not SPD, singular, residual check failed, would not fit in memory).
class NumericalError : public Error {
public:
    using Error::Error;
};
/// A long computation was asked to stop (a real-time run ending while a patch is made): nothing is wrong.
class Cancelled : public Error {
public:
    using Error::Error;
};

}  // namespace aneu
