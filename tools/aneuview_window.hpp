// SPDX-License-Identifier: MIT
#pragma once
#include <vtkRenderWindow.h>
#include <vtkSmartPointer.h>

// An X11 OpenGL render window that copies only its colour into the window (aneuview_window.cpp says why).
vtkSmartPointer<vtkRenderWindow> make_view_window();
