#include "GLContext.h"

#include <cstdio>
#include <cstring>
#include <mutex>
#include <string_view>

#include <EGL/egl.h>
#include <EGL/eglext.h>
#define GL_GLEXT_PROTOTYPES
#include <GL/glcorearb.h>

#include "loom/Error.h"

namespace loom {

namespace {

const char* eglErrorName(EGLint code) {
    switch (code) {
        case EGL_SUCCESS: return "EGL_SUCCESS";
        case EGL_NOT_INITIALIZED: return "EGL_NOT_INITIALIZED";
        case EGL_BAD_ACCESS: return "EGL_BAD_ACCESS";
        case EGL_BAD_ALLOC: return "EGL_BAD_ALLOC";
        case EGL_BAD_ATTRIBUTE: return "EGL_BAD_ATTRIBUTE";
        case EGL_BAD_CONFIG: return "EGL_BAD_CONFIG";
        case EGL_BAD_CONTEXT: return "EGL_BAD_CONTEXT";
        case EGL_BAD_CURRENT_SURFACE: return "EGL_BAD_CURRENT_SURFACE";
        case EGL_BAD_DISPLAY: return "EGL_BAD_DISPLAY";
        case EGL_BAD_MATCH: return "EGL_BAD_MATCH";
        case EGL_BAD_NATIVE_PIXMAP: return "EGL_BAD_NATIVE_PIXMAP";
        case EGL_BAD_NATIVE_WINDOW: return "EGL_BAD_NATIVE_WINDOW";
        case EGL_BAD_PARAMETER: return "EGL_BAD_PARAMETER";
        case EGL_BAD_SURFACE: return "EGL_BAD_SURFACE";
        case EGL_CONTEXT_LOST: return "EGL_CONTEXT_LOST";
        default: return "unknown EGL error";
    }
}

const char kHint[] =
    "Loom needs OpenGL 4.5 core through EGL; on a machine without a GPU Mesa's llvmpipe provides it headless "
    "(Debian: libegl1 libegl-mesa0 libgl1-mesa-dri). Check that MESA_GL_VERSION_OVERRIDE, "
    "MESA_LOADER_DRIVER_OVERRIDE or __EGL_VENDOR_LIBRARY_FILENAMES do not select another driver, or use the "
    "GBufferRT pass instead";

[[noreturn]] void fail(const std::string& call, const std::string& detail) {
    throw Error(Error::Info{ErrorKind::Runtime, {}, "GLContext", call + " failed: " + detail,
                            "a headless OpenGL 4.5 core context (EGL, surfaceless platform)", kHint});
}

[[noreturn]] void failEgl(const std::string& call) {
    const EGLint code = eglGetError();
    char buf[96];
    std::snprintf(buf, sizeof buf, "%s (0x%04X)", eglErrorName(code), unsigned(code));
    fail(call, buf);
}

/// Is `name` a whole word of the space-separated extension list?
bool hasExtension(const char* list, std::string_view name) {
    if (!list) return false;
    std::string_view all(list);
    for (size_t pos = 0; (pos = all.find(name, pos)) != std::string_view::npos; pos += name.size()) {
        const bool startOk = pos == 0 || all[pos - 1] == ' ';
        const bool endOk = pos + name.size() == all.size() || all[pos + name.size()] == ' ';
        if (startOk && endOk) return true;
    }
    return false;
}

// eglTerminate is not reference counted (EGL 1.5, section 3.2: it releases
// every resource of the display at once), and every surfaceless display
// handle of a process is the same object. So several contexts share one
// initialisation, and the last one to go terminates it.
std::mutex gDisplayMutex;
EGLDisplay gDisplay = EGL_NO_DISPLAY;
int gDisplayUsers = 0;

EGLDisplay acquireDisplay() {
    std::lock_guard lock(gDisplayMutex);
    if (gDisplayUsers > 0) {
        ++gDisplayUsers;
        return gDisplay;
    }
    const char* clientExt = eglQueryString(EGL_NO_DISPLAY, EGL_EXTENSIONS);
    if (!clientExt) failEgl("eglQueryString(EGL_NO_DISPLAY, EGL_EXTENSIONS) (no client extensions: EGL < 1.5?)");
    if (!hasExtension(clientExt, "EGL_MESA_platform_surfaceless"))
        fail("eglGetPlatformDisplayEXT",
             "the EGL client extension EGL_MESA_platform_surfaceless is missing (client extensions: " +
                 (*clientExt ? std::string(clientExt) : std::string("none; GLVND found no EGL vendor library")) + ")");
    auto getPlatformDisplay =
        reinterpret_cast<PFNEGLGETPLATFORMDISPLAYEXTPROC>(eglGetProcAddress("eglGetPlatformDisplayEXT"));
    if (!getPlatformDisplay) fail("eglGetProcAddress(\"eglGetPlatformDisplayEXT\")", "EGL_EXT_platform_base missing");
    EGLDisplay display = getPlatformDisplay(EGL_PLATFORM_SURFACELESS_MESA, EGL_DEFAULT_DISPLAY, nullptr);
    if (display == EGL_NO_DISPLAY) failEgl("eglGetPlatformDisplayEXT(EGL_PLATFORM_SURFACELESS_MESA)");
    EGLint major = 0, minor = 0;
    if (!eglInitialize(display, &major, &minor)) failEgl("eglInitialize");
    gDisplay = display;
    gDisplayUsers = 1;
    return display;
}

void releaseDisplay() {
    std::lock_guard lock(gDisplayMutex);
    if (--gDisplayUsers == 0) {
        eglTerminate(gDisplay);
        gDisplay = EGL_NO_DISPLAY;
    }
}

std::string glString(GLenum name) {
    const GLubyte* s = glGetString(name);
    return s ? reinterpret_cast<const char*>(s) : "";
}

}  // namespace

GLContext::GLContext() {
    EGLDisplay display = acquireDisplay();
    mDisplay = display;
    try {
        const char* ext = eglQueryString(display, EGL_EXTENSIONS);
        // Without a config there is no EGLConfig to match; without surfaceless
        // support eglMakeCurrent would need a pbuffer.
        if (!hasExtension(ext, "EGL_KHR_no_config_context") && !hasExtension(ext, "EGL_MESA_configless_context"))
            fail("eglCreateContext", "the display lacks EGL_KHR_no_config_context");
        if (!hasExtension(ext, "EGL_KHR_surfaceless_context"))
            fail("eglMakeCurrent", "the display lacks EGL_KHR_surfaceless_context");
        if (!eglBindAPI(EGL_OPENGL_API)) failEgl("eglBindAPI(EGL_OPENGL_API)");
        // EGL 1.5 / EGL_KHR_create_context attributes: desktop GL 4.5, core profile.
        const EGLint attribs[] = {EGL_CONTEXT_MAJOR_VERSION,
                                  4,
                                  EGL_CONTEXT_MINOR_VERSION,
                                  5,
                                  EGL_CONTEXT_OPENGL_PROFILE_MASK,
                                  EGL_CONTEXT_OPENGL_CORE_PROFILE_BIT,
                                  EGL_NONE};
        EGLContext context = eglCreateContext(display, EGL_NO_CONFIG_KHR, EGL_NO_CONTEXT, attribs);
        if (context == EGL_NO_CONTEXT) failEgl("eglCreateContext(OpenGL 4.5 core profile)");
        mContext = context;
        Scope scope(*this);
        GLint glMajor = 0, glMinor = 0;
        glGetIntegerv(GL_MAJOR_VERSION, &glMajor);
        glGetIntegerv(GL_MINOR_VERSION, &glMinor);
        mRenderer = glString(GL_RENDERER);
        mVersion = glString(GL_VERSION);
        if (glMajor * 10 + glMinor < 45)
            fail("eglCreateContext", "the context reports OpenGL " + mVersion + " (" + mRenderer + "), not 4.5");
    } catch (...) {
        if (mContext) eglDestroyContext(display, mContext);
        mContext = nullptr;
        releaseDisplay();
        throw;
    }
}

GLContext::~GLContext() {
    // Destroying an unshared context frees every GL object it owns.
    if (mContext) eglDestroyContext(mDisplay, mContext);
    releaseDisplay();
}

GLContext::Scope::Scope(GLContext& context) : mContext(context) {
    // eglGetCurrentContext and eglMakeCurrent act on the thread's bound client
    // API (EGL 1.5, section 3.7), so bind desktop GL for the scope.
    mPrevApi = eglQueryAPI();
    if (mPrevApi != EGL_OPENGL_API) eglBindAPI(EGL_OPENGL_API);
    mPrevContext = eglGetCurrentContext();
    if (mPrevContext == context.mContext) return;
    mPrevDisplay = eglGetCurrentDisplay();
    mPrevDraw = eglGetCurrentSurface(EGL_DRAW);
    mPrevRead = eglGetCurrentSurface(EGL_READ);
    if (!eglMakeCurrent(context.mDisplay, EGL_NO_SURFACE, EGL_NO_SURFACE, context.mContext)) {
        if (mPrevApi != EGL_OPENGL_API) eglBindAPI(mPrevApi);
        failEgl("eglMakeCurrent (is the context current on another thread?)");
    }
    mSwitched = true;
}

GLContext::Scope::~Scope() {
    if (mSwitched) {
        if (mPrevContext != EGL_NO_CONTEXT)
            eglMakeCurrent(mPrevDisplay, mPrevDraw, mPrevRead, mPrevContext);
        else
            eglMakeCurrent(mContext.mDisplay, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT);
    }
    if (mPrevApi != EGL_OPENGL_API) eglBindAPI(mPrevApi);
}

}  // namespace loom
