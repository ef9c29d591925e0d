// SPDX-License-Identifier: MIT
#pragma once
/// @file
/// Medical image I/O and filtering through ITK, behind standard types (ITK's bundled Eigen must not meet
/// ours, so ITK headers stay in image_io_itk.cpp). Geometry is the physical LPS frame as ITK reports it.
#include <cstdint>
#include <string>

#include "aneu/core/image_grid.hpp"

namespace aneu::pipeline {

/// Reads a volume: a .nii/.nii.gz, .nrrd/.nhdr or .mha/.mhd file, or a directory holding one DICOM
/// series (GDCM), converted to T.
/// @throws InputError unsupported extension, missing path, several or no DICOM series;
///         IoError  the file cannot be read (ITK's message kept)
template <class T>
Volume<T> read_image(const std::string& path);

/// Writes a volume as .nii.gz/.nii, .nrrd or .mha (by extension), compressed.
/// @throws InputError unsupported extension; IoError  write failure
template <class T>
void write_image(const std::string& path, const Volume<T>& v);

/// Descriptive DICOM attributes of a written series.
struct DicomSeriesInfo {
    std::string patient_name = "ANEUCLIP^PHANTOM";
    std::string patient_id = "PHANTOM";
    std::string study_description = "aneuclip synthetic CTA";
    std::string series_description = "phantom";
};
/// Writes a CT volume as a DICOM series (one file per k-slice, IM0001.dcm ...) into an existing directory,
/// with ImagePositionPatient/ImageOrientationPatient/PixelSpacing from the grid.
void write_dicom_series(const std::string& dir, const Volume<std::int16_t>& v, const DicomSeriesInfo& info);

/// Gaussian smoothing with a standard deviation in mm (recursive Gaussian, spacing-aware).
Volume<float> gaussian_blur(const Volume<float>& v, double sigma_mm);

}  // namespace aneu::pipeline
