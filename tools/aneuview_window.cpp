// SPDX-License-Identifier: MIT
// aneuview's render window: VTK's X11 OpenGL window without the depth copy into the window (issue #18, frame rate
// under software rendering). Kept out of aneuview.cpp because the X11 headers define macros (None, Status, Bool).
//
// VTK 9.1 renders into its own framebuffer, copies it (colour and depth) to its display framebuffer, then
// (BlitDisplayFramebuffersToHardware) copies the display framebuffer's depth to the window by drawing a full-window
// textured quad that writes gl_FragDepth, and its colour by a blit. Nothing draws into the window after VTK, and VTK
// reads pixels and depth back from its own framebuffers, so the window's depth is never used: the quad is a
// full-window fragment-shader pass for nothing, which a software renderer (Xvfb's llvmpipe) pays in full.
// Measured (bench/results/view.md, session 30): an empty 900 x 700 frame 5.1-5.7 ms with it, 2.9 ms without.
#include "aneuview_window.hpp"

#include <vtkObjectFactory.h>
#include <vtkOpenGLFramebufferObject.h>
#include <vtkOpenGLState.h>
#include <vtkXOpenGLRenderWindow.h>
#include <vtk_glew.h>

namespace {

class ColourToWindow : public vtkXOpenGLRenderWindow {
public:
    static ColourToWindow* New();
    vtkTypeMacro(ColourToWindow, vtkXOpenGLRenderWindow)

protected:
    ColourToWindow() = default;
    void BlitDisplayFramebuffersToHardware() override {
        // Quad-buffered stereo copies two buffers: VTK's own path (aneuview's stereo is a split viewport).
        if (this->StereoRender && this->StereoType == VTK_STEREO_CRYSTAL_EYES) {
            vtkXOpenGLRenderWindow::BlitDisplayFramebuffersToHardware();
            return;
        }
        vtkOpenGLState* st = this->GetState();
        st->PushFramebufferBindings();
        st->vtkglViewport(0, 0, this->Size[0], this->Size[1]);
        st->vtkglScissor(0, 0, this->Size[0], this->Size[1]);
        st->vtkglBindFramebuffer(GL_DRAW_FRAMEBUFFER, 0);
        st->vtkglDrawBuffer(this->DoubleBuffer ? GL_BACK_LEFT : GL_FRONT_LEFT);
        this->DisplayFramebuffer->Bind(GL_READ_FRAMEBUFFER);
        this->DisplayFramebuffer->ActivateReadBuffer(0);
        st->vtkglBlitFramebuffer(0, 0, this->Size[0], this->Size[1], 0, 0, this->Size[0], this->Size[1], GL_COLOR_BUFFER_BIT, GL_NEAREST);
        st->PopFramebufferBindings();
    }
};

vtkStandardNewMacro(ColourToWindow)

}  // namespace

vtkSmartPointer<vtkRenderWindow> make_view_window() { return vtkSmartPointer<ColourToWindow>::New(); }
