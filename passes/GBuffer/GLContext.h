#pragma once
// A headless OpenGL 4.5 core context from EGL, with no window and no X server:
// Mesa's surfaceless platform (EGL_MESA_platform_surfaceless) with a
// configless context (EGL_KHR_no_config_context) and no default framebuffer
// (EGL_KHR_surfaceless_context). Rendering goes to framebuffer objects.
//
// GL entry points come straight from libOpenGL (GLVND), which dispatches to
// whichever context is current on the calling thread, so the context must be
// current (see Scope) around every GL call.
#include <string>

namespace loom {

class GLContext {
public:
    /// Creates the display connection and a 4.5 core context. Throws
    /// loom::Error (Runtime) naming the failing EGL call, its error code and
    /// a hint when EGL, the surfaceless platform or GL 4.5 is unavailable.
    GLContext();
    ~GLContext();
    GLContext(const GLContext&) = delete;
    GLContext& operator=(const GLContext&) = delete;

    /// Makes the context current on the calling thread for the scope's life
    /// and restores the previously current EGL context (or none) afterwards,
    /// so a viewer's own context is not left displaced. A GLX context (GLFW
    /// on X11) is not visible to EGL: such a caller must make it current
    /// again itself, as GLFW applications do each frame anyway.
    class Scope {
    public:
        explicit Scope(GLContext& context);
        ~Scope();
        Scope(const Scope&) = delete;
        Scope& operator=(const Scope&) = delete;

    private:
        GLContext& mContext;
        void* mPrevDisplay = nullptr;
        void* mPrevDraw = nullptr;
        void* mPrevRead = nullptr;
        void* mPrevContext = nullptr;
        unsigned mPrevApi = 0;
        bool mSwitched = false;
    };

    /// GL_RENDERER and GL_VERSION strings, e.g. "llvmpipe (LLVM 15.0.6, 256 bits)".
    const std::string& renderer() const { return mRenderer; }
    const std::string& version() const { return mVersion; }

private:
    void* mDisplay = nullptr;  // EGLDisplay (void* keeps <EGL/egl.h> out of this header)
    void* mContext = nullptr;  // EGLContext
    std::string mRenderer, mVersion;
};

}  // namespace loom
