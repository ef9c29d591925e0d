// SPDX-License-Identifier: MIT
// ITK filters of the segmentation. This translation unit includes ITK and must not include Eigen.
#include <algorithm>
#include <cmath>

#include <itkBinaryFillholeImageFilter.h>
#include <itkConnectedComponentImageFilter.h>
#include <itkConnectedThresholdImageFilter.h>
#include <itkGradientAnisotropicDiffusionImageFilter.h>
#include <itkHessianToObjectnessMeasureImageFilter.h>
#include <itkMultiScaleHessianBasedMeasureImageFilter.h>
#include <itkSymmetricSecondRankTensor.h>
#include <itkOtsuThresholdCalculator.h>
#include <itkRelabelComponentImageFilter.h>
#include <itkScalarImageToHistogramGenerator.h>

#include "aneu/core/error.hpp"
#include "aneu/pipeline/image_filters.hpp"
#include "itk_convert.hpp"

namespace aneu::pipeline {

using itkconv::Img;
using itkconv::from_itk;
using itkconv::to_itk;

namespace {
template <class F>
void update(F& f, const char* what) {
    try {
        f->Update();
    } catch (const itk::ExceptionObject& e) {
        throw Error(std::string(what) + ": ITK: " + e.GetDescription());
    }
}
}  // namespace

Volume<float> anisotropic_diffusion(const Volume<float>& v, int iterations, double conductance_hu) {
    if (iterations <= 0) return v;
    auto f = itk::GradientAnisotropicDiffusionImageFilter<Img<float>, Img<float>>::New();
    f->SetInput(to_itk(v));
    f->SetNumberOfIterations(static_cast<unsigned>(iterations));
    const double hmin = std::min({v.grid.spacing[0], v.grid.spacing[1], v.grid.spacing[2]});
    f->SetTimeStep(hmin / 16.0 * 0.99);  // stability bound min spacing / 2^(N+1), N = 3
    f->SetConductanceParameter(conductance_hu);
    f->SetUseImageSpacing(true);
    // The conductance is in HU: do not rescale it by the gradient magnitude's average.
    f->SetFixedAverageGradientMagnitude(1.0);
    update(f, "anisotropic diffusion");
    return from_itk<float>(f->GetOutput());
}

Volume<std::uint8_t> connected_threshold(const Volume<float>& v, float lower, float upper, const std::vector<Index3>& seeds) {
    auto f = itk::ConnectedThresholdImageFilter<Img<float>, Img<std::uint8_t>>::New();
    f->SetInput(to_itk(v));
    f->SetLower(lower);
    f->SetUpper(upper);
    f->SetReplaceValue(1);
    f->SetConnectivity(itk::ConnectedThresholdImageFilter<Img<float>, Img<std::uint8_t>>::FullConnectivity);
    for (const auto& s : seeds) {
        Img<float>::IndexType idx;
        for (int d = 0; d < 3; ++d) idx[d] = s[static_cast<size_t>(d)];
        f->AddSeed(idx);
    }
    update(f, "connected threshold");
    return from_itk<std::uint8_t>(f->GetOutput());
}

Components connected_components(const Volume<std::uint8_t>& m, bool full_connectivity) {
    auto cc = itk::ConnectedComponentImageFilter<Img<std::uint8_t>, Img<std::int32_t>>::New();
    cc->SetInput(to_itk(m));
    cc->SetFullyConnected(full_connectivity);
    auto rl = itk::RelabelComponentImageFilter<Img<std::int32_t>, Img<std::int32_t>>::New();
    rl->SetInput(cc->GetOutput());
    update(rl, "connected components");
    Components c;
    c.labels = from_itk<std::int32_t>(rl->GetOutput());
    for (auto n : rl->GetSizeOfObjectsInPixels()) c.sizes.push_back(static_cast<std::int64_t>(n));
    return c;
}

Volume<std::uint8_t> fill_holes(const Volume<std::uint8_t>& m) {
    auto f = itk::BinaryFillholeImageFilter<Img<std::uint8_t>>::New();
    f->SetInput(to_itk(m));
    f->SetForegroundValue(1);
    f->SetFullyConnected(true);
    update(f, "hole filling");
    return from_itk<std::uint8_t>(f->GetOutput());
}

double otsu_threshold(const Volume<float>& v, const std::vector<std::uint8_t>& roi) {
    std::vector<float> vals;
    vals.reserve(v.data.size());
    for (size_t i = 0; i < v.data.size(); ++i)
        if (roi.empty() || roi[i]) vals.push_back(v.data[i]);
    if (vals.empty()) throw InputError("otsu threshold: the region holds no voxel");
    // Histogram through ITK's sample/histogram framework on a 1-D image of the ROI values.
    Volume<float> line;
    line.grid.size = {static_cast<std::int64_t>(vals.size()), 1, 1};
    line.data = std::move(vals);
    using Gen = itk::Statistics::ScalarImageToHistogramGenerator<Img<float>>;
    auto gen = Gen::New();
    auto im = to_itk(line);
    gen->SetInput(im);
    gen->SetNumberOfBins(256);
    gen->Compute();
    auto calc = itk::OtsuThresholdCalculator<Gen::HistogramType, double>::New();
    calc->SetInput(gen->GetOutput());
    update(calc, "Otsu threshold");
    return calc->GetThreshold();
}

Volume<float> vesselness(const Volume<float>& v, double sigma_min_mm, double sigma_max_mm, int steps) {
    using Hessian = itk::SymmetricSecondRankTensor<double, 3>;
    using HessianImage = itk::Image<Hessian, 3>;
    auto objectness = itk::HessianToObjectnessMeasureImageFilter<HessianImage, Img<float>>::New();
    objectness->SetObjectDimension(1);  // tubes
    objectness->SetBrightObject(true);
    objectness->SetScaleObjectnessMeasure(false);
    objectness->SetAlpha(0.5);
    objectness->SetBeta(0.5);
    objectness->SetGamma(50.0);  // HU: structures of lower Hessian contrast (noise, soft tissue texture) score low
    auto multi = itk::MultiScaleHessianBasedMeasureImageFilter<Img<float>, HessianImage, Img<float>>::New();
    multi->SetInput(to_itk(v));
    multi->SetHessianToMeasureFilter(objectness);
    multi->SetSigmaMinimum(sigma_min_mm);
    multi->SetSigmaMaximum(sigma_max_mm);
    multi->SetNumberOfSigmaSteps(static_cast<unsigned>(std::max(1, steps)));
    multi->SetSigmaStepMethodToLogarithmic();
    multi->SetGenerateScalesOutput(false);
    multi->SetGenerateHessianOutput(false);
    update(multi, "vesselness");
    return from_itk<float>(multi->GetOutput());
}

}  // namespace aneu::pipeline
