// SPDX-License-Identifier: MIT
// The ITK side of image I/O. This translation unit includes ITK and must not include Eigen (ITK 5.2
// ships its own Eigen 3.3.9 unmangled; DESIGN.md "Known pitfalls").
#include <algorithm>
#include <filesystem>

#include <itkGDCMImageIO.h>
#include <itkGDCMSeriesFileNames.h>
#include <itkImage.h>
#include <itkImageFileReader.h>
#include <itkImageFileWriter.h>
#include <itkImageSeriesReader.h>
#include <itkImageSeriesWriter.h>
#include <itkMetaDataObject.h>
#include <itkMetaImageIO.h>
#include <itkNiftiImageIO.h>
#include <itkNrrdImageIO.h>
#include <itkNumericSeriesFileNames.h>
#include <itkSmoothingRecursiveGaussianImageFilter.h>

#include "aneu/core/error.hpp"
#include "aneu/pipeline/image_io.hpp"
#include "itk_convert.hpp"

namespace aneu::pipeline {

namespace fs = std::filesystem;
using itkconv::Img;
using itkconv::from_itk;
using itkconv::to_itk;

namespace {

bool ends_with(const std::string& s, const std::string& suffix) {
    if (s.size() < suffix.size()) return false;
    return std::equal(suffix.rbegin(), suffix.rend(), s.rbegin(),
                      [](char a, char b) { return std::tolower(static_cast<unsigned char>(a)) == b; });
}

/// The ImageIO for a file name, chosen by extension (explicit: no factory registration needed).
itk::ImageIOBase::Pointer io_for(const std::string& path) {
    if (ends_with(path, ".nii") || ends_with(path, ".nii.gz")) return itk::NiftiImageIO::New().GetPointer();
    if (ends_with(path, ".nrrd") || ends_with(path, ".nhdr")) return itk::NrrdImageIO::New().GetPointer();
    if (ends_with(path, ".mha") || ends_with(path, ".mhd")) return itk::MetaImageIO::New().GetPointer();
    throw InputError(path + ": unsupported image format (expected .nii, .nii.gz, .nrrd, .nhdr, .mha, .mhd, or a "
                            "directory with a DICOM series)");
}


template <class T>
Volume<T> read_dicom_dir(const std::string& dir) {
    auto names = itk::GDCMSeriesFileNames::New();
    names->SetUseSeriesDetails(true);
    names->SetDirectory(dir);
    const auto uids = names->GetSeriesUIDs();
    if (uids.empty()) throw InputError(dir + ": directory holds no DICOM series");
    if (uids.size() > 1) {
        throw InputError(dir + ": directory holds " + std::to_string(uids.size()) +
                         " DICOM series; put the CT angiography series in a directory of its own");
    }
    auto reader = itk::ImageSeriesReader<Img<T>>::New();
    reader->SetImageIO(itk::GDCMImageIO::New());
    reader->SetFileNames(names->GetFileNames(uids.front()));
    reader->Update();
    return from_itk<T>(reader->GetOutput());
}

}  // namespace

template <class T>
Volume<T> read_image(const std::string& path) {
    std::error_code ec;
    if (!fs::exists(path, ec)) throw InputError(path + ": no such file or directory (expected a CT volume)");
    try {
        if (fs::is_directory(path, ec)) return read_dicom_dir<T>(path);
        auto reader = itk::ImageFileReader<Img<T>>::New();
        reader->SetImageIO(io_for(path));
        reader->SetFileName(path);
        reader->Update();
        return from_itk<T>(reader->GetOutput());
    } catch (const itk::ExceptionObject& e) {
        throw InputError(path + ": cannot read image (ITK: " + std::string(e.GetDescription()) + ")");
    }
}

template <class T>
void write_image(const std::string& path, const Volume<T>& v) {
    auto io = io_for(path);
    auto im = to_itk(v);
    try {
        auto writer = itk::ImageFileWriter<Img<T>>::New();
        writer->SetImageIO(io);
        writer->SetFileName(path);
        writer->SetInput(im);
        writer->SetUseCompression(true);
        writer->Update();
    } catch (const itk::ExceptionObject& e) {
        throw IoError(path + ": cannot write image (ITK: " + std::string(e.GetDescription()) + ")");
    }
}

void write_dicom_series(const std::string& dir, const Volume<std::int16_t>& v, const DicomSeriesInfo& info) {
    auto im = to_itk(v);
    auto gdcm = itk::GDCMImageIO::New();
    itk::MetaDataDictionary& dict = gdcm->GetMetaDataDictionary();
    itk::EncapsulateMetaData<std::string>(dict, "0008|0060", "CT");
    itk::EncapsulateMetaData<std::string>(dict, "0028|0004", "MONOCHROME2");
    itk::EncapsulateMetaData<std::string>(dict, "0008|0008", "DERIVED\\SECONDARY\\AXIAL");
    itk::EncapsulateMetaData<std::string>(dict, "0010|0010", info.patient_name);
    itk::EncapsulateMetaData<std::string>(dict, "0010|0020", info.patient_id);
    itk::EncapsulateMetaData<std::string>(dict, "0008|1030", info.study_description);
    itk::EncapsulateMetaData<std::string>(dict, "0008|103e", info.series_description);
    itk::EncapsulateMetaData<std::string>(dict, "0018|0050", std::to_string(v.grid.spacing[2]));
    itk::EncapsulateMetaData<std::string>(dict, "0028|1052", "0");  // rescale intercept: stored = HU
    itk::EncapsulateMetaData<std::string>(dict, "0028|1053", "1");  // rescale slope
    auto names = itk::NumericSeriesFileNames::New();
    names->SetStartIndex(1);
    names->SetEndIndex(static_cast<itk::SizeValueType>(v.grid.size[2]));
    names->SetIncrementIndex(1);
    names->SetSeriesFormat((fs::path(dir) / "IM%04d.dcm").string());
    try {
        auto writer = itk::ImageSeriesWriter<Img<std::int16_t>, itk::Image<std::int16_t, 2>>::New();
        writer->SetInput(im);
        writer->SetImageIO(gdcm);
        writer->SetFileNames(names->GetFileNames());
        writer->Update();  // no dictionary array: ITK sets each slice's position and orientation
    } catch (const itk::ExceptionObject& e) {
        throw IoError(dir + ": cannot write DICOM series (ITK: " + std::string(e.GetDescription()) + ")");
    }
}

Volume<float> gaussian_blur(const Volume<float>& v, double sigma_mm) {
    if (!(sigma_mm > 0.0)) return v;
    auto im = to_itk(v);
    auto f = itk::SmoothingRecursiveGaussianImageFilter<Img<float>, Img<float>>::New();
    f->SetInput(im);
    f->SetSigma(sigma_mm);
    f->Update();
    Volume<float> out = from_itk<float>(f->GetOutput());
    return out;
}

template Volume<std::int16_t> read_image<std::int16_t>(const std::string&);
template Volume<std::uint8_t> read_image<std::uint8_t>(const std::string&);
template Volume<float> read_image<float>(const std::string&);
template void write_image<std::int16_t>(const std::string&, const Volume<std::int16_t>&);
template void write_image<std::uint8_t>(const std::string&, const Volume<std::uint8_t>&);
template void write_image<float>(const std::string&, const Volume<float>&);

}  // namespace aneu::pipeline
