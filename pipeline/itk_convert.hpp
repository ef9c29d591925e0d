// SPDX-License-Identifier: MIT
#pragma once
// Internal to pipeline/: conversion between aneu::Volume and itk::Image. Include only from translation
// units that include ITK and not Eigen (DESIGN.md "Known pitfalls").
#include <itkImage.h>

#include <string>

#include "aneu/core/error.hpp"
#include "aneu/core/image_grid.hpp"

namespace aneu::pipeline::itkconv {

template <class T>
using Img = itk::Image<T, 3>;

template <class T>
inline Volume<T> from_itk(const Img<T>* im) {
    Volume<T> v;
    const auto size = im->GetLargestPossibleRegion().GetSize();
    for (int d = 0; d < 3; ++d) {
        v.grid.size[d] = static_cast<std::int64_t>(size[d]);
        v.grid.origin[d] = im->GetOrigin()[d];
        v.grid.spacing[d] = im->GetSpacing()[d];
        for (int c = 0; c < 3; ++c) v.grid.direction[3 * d + c] = im->GetDirection()(d, c);
    }
    const T* p = im->GetBufferPointer();
    v.data.assign(p, p + v.grid.voxel_count());
    return v;
}

template <class T>
inline typename Img<T>::Pointer to_itk(const Volume<T>& v) {
    if (v.data.size() != v.grid.voxel_count()) {
        throw InputError("image: " + std::to_string(v.data.size()) + " voxels for a grid of " +
                         std::to_string(v.grid.voxel_count()));
    }
    auto im = Img<T>::New();
    typename Img<T>::SizeType size;
    typename Img<T>::PointType origin;
    typename Img<T>::SpacingType spacing;
    typename Img<T>::DirectionType dir;
    for (int d = 0; d < 3; ++d) {
        size[d] = static_cast<itk::SizeValueType>(v.grid.size[d]);
        origin[d] = v.grid.origin[d];
        spacing[d] = v.grid.spacing[d];
        for (int c = 0; c < 3; ++c) dir(d, c) = v.grid.direction[3 * d + c];
    }
    im->SetRegions(typename Img<T>::RegionType(size));
    im->SetOrigin(origin);
    im->SetSpacing(spacing);
    im->SetDirection(dir);
    im->Allocate();
    std::copy(v.data.begin(), v.data.end(), im->GetBufferPointer());
    return im;
}

}  // namespace aneu::pipeline::itkconv
