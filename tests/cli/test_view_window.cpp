// SPDX-License-Identifier: MIT
// aneuview's render window (tools/aneuview_window.cpp) copies only VTK's colour into the X window, not its depth
// (issue #18, the software-rendered frame rate). What the X server shows must still be what VTK rendered: a red
// sphere on white, read back from the window by XGetImage, pixel for pixel equal to VTK's own framebuffer at the
// centre, the corners and along a row across the sphere's edge, over several frames with the camera turning.
// Run under Xvfb (scripts/xvfb.sh). Exit 0: equal; 1: a pixel differs (printed).
#include <cstdio>

#include <vtkActor.h>
#include <vtkCamera.h>
#include <vtkNew.h>
#include <vtkPolyDataMapper.h>
#include <vtkProperty.h>
#include <vtkRenderer.h>
#include <vtkSphereSource.h>

#include "aneuview_window.hpp"

#include <X11/Xlib.h>  // last: its macros (None, Status, Bool)
#include <X11/Xutil.h>

int main() {
    const int w = 320, h = 200;
    const vtkSmartPointer<vtkRenderWindow> win = make_view_window();
    win->SetSize(w, h);
    win->SetMultiSamples(0);
    vtkNew<vtkRenderer> ren;
    win->AddRenderer(ren);
    ren->SetBackground(1, 1, 1);
    vtkNew<vtkSphereSource> sphere;
    vtkNew<vtkPolyDataMapper> mapper;
    mapper->SetInputConnection(sphere->GetOutputPort());
    vtkNew<vtkActor> actor;
    actor->SetMapper(mapper);
    actor->GetProperty()->SetColor(1, 0, 0);
    actor->GetProperty()->SetAmbient(1);
    actor->GetProperty()->SetDiffuse(0);
    ren->AddActor(actor);
    Display* display = nullptr;  // the window's, once the first render made it
    int bad = 0, checked = 0, red = 0;
    for (int frame = 0; frame < 4; ++frame) {
        win->Render();
        if (frame == 0) {
            ren->ResetCamera();
            ren->GetActiveCamera()->Zoom(0.8);
            display = static_cast<Display*>(win->GetGenericDisplayId());
            continue;
        }
        ren->GetActiveCamera()->Azimuth(20);
        win->Render();
        XSync(display, False);
        XImage* image = XGetImage(display, static_cast<Window>(reinterpret_cast<uintptr_t>(win->GetGenericWindowId())), 0, 0, w, h, AllPlanes, ZPixmap);
        if (!image) {
            std::fprintf(stderr, "test_view_window: XGetImage of the window failed\n");
            return 1;
        }
        unsigned char* vtk = win->GetPixelData(0, 0, w - 1, h - 1, 1);  // rows bottom up
        auto compare = [&](int x, int y) {
            const unsigned long px = XGetPixel(image, x, y);
            const unsigned char* v = vtk + 3 * ((h - 1 - y) * w + x);
            const unsigned r = (px >> 16) & 0xff, g = (px >> 8) & 0xff, b = px & 0xff;
            ++checked;
            if (r == 255 && g == 0 && b == 0) ++red;
            if (r != v[0] || g != v[1] || b != v[2]) {
                if (++bad <= 10) std::printf("frame %d pixel (%d, %d): window %02x%02x%02x, VTK %02x%02x%02x\n", frame, x, y, r, g, b, v[0], v[1], v[2]);
            }
        };
        for (int x = 0; x < w; ++x) compare(x, h / 2);
        compare(0, 0);
        compare(w - 1, 0);
        compare(0, h - 1);
        compare(w - 1, h - 1);
        delete[] vtk;
        XDestroyImage(image);
    }
    std::printf("%d pixels compared, %d red (the sphere), %d differ\n", checked, red, bad);
    return bad == 0 && red > 0 && red < checked ? 0 : 1;
}
