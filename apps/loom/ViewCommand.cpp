// loom view: run a graph in a window, Mogwai-style. Pick any field to show (history included) without disturbing
// the render, tune every pass's parameters from their declarations, pause, step, reset history, reload the graph
// file when it is edited, save the shown field or the screen, record every frame. --headless runs the same session
// without a window (scripts, tests, machines without a display).
#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <memory>
#include <nlohmann/json.hpp>

#include "CliUtil.h"
#include "Display.h"
#include "Interrupt.h"
#include "ViewSession.h"
#include "loom/Error.h"
#include "loom/ImageIO.h"

#ifdef LOOM_HAVE_VIEWER
#define GLFW_INCLUDE_NONE
#include <GL/gl.h>
#include <GLFW/glfw3.h>
#include <imgui.h>
#include <imgui_impl_glfw.h>
#include <imgui_impl_opengl3.h>
#endif

namespace loom::cli {

namespace {

#ifdef LOOM_HAVE_VIEWER

constexpr float kPanelWidth = 360.f;

/// One parameter's widget, from its declaration; an edit goes through RenderGraph::setParam (never reallocates).
/// Returns the error of a rejected edit, else empty.
std::string paramWidget(ViewSession& session, const std::string& pass, const ParamDecl& d) {
    nlohmann::json value = d.get(), edited;
    const char* label = d.name.c_str();
    switch (d.type) {
        case ParamType::Bool: {
            bool v = value.get<bool>();
            if (ImGui::Checkbox(label, &v)) edited = v;
            break;
        }
        case ParamType::Int: {
            int v = value.get<int>();
            const bool ranged = d.min && d.max && *d.max - *d.min <= 1024;
            if (ranged ? ImGui::SliderInt(label, &v, int(*d.min), int(*d.max)) : ImGui::InputInt(label, &v)) edited = v;
            break;
        }
        case ParamType::Float: {
            float v = value.get<float>();
            const bool ranged = d.min && d.max && *d.max - *d.min <= 1e4;
            if (ranged ? ImGui::SliderFloat(label, &v, float(*d.min), float(*d.max), "%.4g")
                       : ImGui::DragFloat(label, &v, 0.01f * std::max(1.f, std::fabs(v)), 0.f, 0.f, "%.4g"))
                edited = v;
            break;
        }
        case ParamType::Enum: {
            const std::string current = value.get<std::string>();
            if (ImGui::BeginCombo(label, current.c_str())) {
                for (const std::string& option : d.enumValues)
                    if (ImGui::Selectable(option.c_str(), option == current)) edited = option;
                ImGui::EndCombo();
            }
            break;
        }
        case ParamType::Vec3:
        case ParamType::Vec4: {
            float v[4] = {};
            const int n = d.type == ParamType::Vec3 ? 3 : 4;
            for (int i = 0; i < n; ++i) v[i] = value[size_t(i)].get<float>();
            if (n == 3 ? ImGui::DragFloat3(label, v, 0.01f) : ImGui::DragFloat4(label, v, 0.01f))
                edited = std::vector<float>(v, v + n);
            break;
        }
        case ParamType::String:
            ImGui::Text("%s: %s", label, value.get<std::string>().c_str());
            break;
    }
    if (ImGui::IsItemHovered() && !d.doc.empty()) ImGui::SetTooltip("%s", d.doc.c_str());
    if (edited.is_null()) return {};
    try {
        session.graph().setParam(pass, d.name, edited, "viewer " + pass + "." + d.name);
    } catch (const Error& e) {
        return e.what();
    }
    return {};
}

class Window {
public:
    explicit Window(const ViewSession& session) : mOpenPasses(session.options().openPasses) {
        glfwSetErrorCallback([](int, const char* text) { spdlog::debug("GLFW: {}", text); });
        if (!glfwInit())
            throw Error({ErrorKind::Runtime,
                         {},
                         "loom view",
                         "no display to open a window on",
                         "",
                         "set DISPLAY, run under xvfb-run, or use --headless"});
        glfwWindowHint(GLFW_CONTEXT_VERSION_MAJOR, 3);
        glfwWindowHint(GLFW_CONTEXT_VERSION_MINOR, 3);
        glfwWindowHint(GLFW_OPENGL_PROFILE, GLFW_OPENGL_CORE_PROFILE);
        const int w = int(std::clamp<uint32_t>(session.width(), 320, 1920) + kPanelWidth);
        const int h = int(std::clamp<uint32_t>(session.height(), 480, 1080));
        mWindow = glfwCreateWindow(w, h, ("Loom - " + session.options().graph).c_str(), nullptr, nullptr);
        if (!mWindow) {
            glfwTerminate();
            throw Error({ErrorKind::Runtime,
                         {},
                         "loom view",
                         "could not create an OpenGL 3.3 window",
                         "",
                         "check the display's OpenGL support, or use --headless"});
        }
        glfwMakeContextCurrent(mWindow);
        glfwSwapInterval(0);
        IMGUI_CHECKVERSION();
        ImGui::CreateContext();
        ImGui::GetIO().IniFilename = nullptr;
        ImGui::StyleColorsDark();
        ImGui_ImplGlfw_InitForOpenGL(mWindow, true);
        ImGui_ImplOpenGL3_Init("#version 330");
        glGenTextures(1, &mTexture);
        glBindTexture(GL_TEXTURE_2D, mTexture);
        glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_LINEAR);
        glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_NEAREST);  // magnified pixels stay pixels
    }
    ~Window() {
        glfwMakeContextCurrent(mWindow);
        glDeleteTextures(1, &mTexture);
        ImGui_ImplOpenGL3_Shutdown();
        ImGui_ImplGlfw_Shutdown();
        ImGui::DestroyContext();
        glfwDestroyWindow(mWindow);
        glfwTerminate();
    }
    bool open() const { return !glfwWindowShouldClose(mWindow); }
    /// Makes no context current: passes that render with their own (EGL) context cannot while the window's is.
    void release() { glfwMakeContextCurrent(nullptr); }

    /// Draws one frame of the window: the shown field fitted to the left, the panel on the right.
    /// With `capture`, the frame drawn is also read back and written there as PNG (no tooltip in it).
    void draw(ViewSession& session, bool& paused, bool& stepOnce, double renderMs, const std::string& capture = {}) {
        glfwPollEvents();
        glfwMakeContextCurrent(mWindow);  // released while the graph ran
        const Texture& shown = session.viewedTexture();
        if (!session.display().empty() && session.displayVersion() != mUploaded) {
            mUploaded = session.displayVersion();
            glBindTexture(GL_TEXTURE_2D, mTexture);
            glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
            glTexImage2D(GL_TEXTURE_2D, 0, GL_RGBA8, GLsizei(shown.width()), GLsizei(shown.height()), 0, GL_RGBA,
                         GL_UNSIGNED_BYTE, session.display().data());
        }
        ImGui_ImplOpenGL3_NewFrame();
        ImGui_ImplGlfw_NewFrame();
        ImGui::NewFrame();
        int fw, fh;
        glfwGetFramebufferSize(mWindow, &fw, &fh);
        const ImVec2 size = ImGui::GetIO().DisplaySize;
        const float areaW = std::max(1.f, size.x - kPanelWidth), areaH = std::max(1.f, size.y);
        if (!session.display().empty()) {
            navigate(shown, areaW, areaH);
            const ImagePlacement at = mViewport.place(areaW, areaH, shown.width(), shown.height());
            mShownScale = at.scale;
            ImDrawList* list = ImGui::GetBackgroundDrawList();
            list->PushClipRect(ImVec2(0.f, 0.f), ImVec2(areaW, areaH));  // a zoomed image stays left of the panel
            list->AddImage(reinterpret_cast<ImTextureID>(uintptr_t(mTexture)), ImVec2(at.x0, at.y0),
                           ImVec2(at.x0 + float(shown.width()) * at.scale, at.y0 + float(shown.height()) * at.scale));
            list->PopClipRect();
            if (capture.empty()) inspect(shown, at, areaW);
        }
        panel(session, paused, stepOnce, renderMs, areaW, areaH);
        ImGui::Render();
        glViewport(0, 0, fw, fh);
        glClearColor(0.08f, 0.08f, 0.08f, 1.f);
        glClear(GL_COLOR_BUFFER_BIT);
        ImGui_ImplOpenGL3_RenderDrawData(ImGui::GetDrawData());
        if (!capture.empty()) writeFramebuffer(capture, fw, fh);
        glfwSwapBuffers(mWindow);
    }

    /// The camera from the keyboard and mouse while the panel does not want them: W, A, S, D, Q, E move (a quarter
    /// of the scene's size a second, Shift four times that), the right mouse button held turns.
    void steer(ViewSession& session, double seconds) {
        const ImGuiIO& io = ImGui::GetIO();
        glm::vec3 move(0.f);
        if (!io.WantCaptureKeyboard) {
            const auto key = [&](int k) { return glfwGetKey(mWindow, k) == GLFW_PRESS ? 1.f : 0.f; };
            move = glm::vec3(key(GLFW_KEY_D) - key(GLFW_KEY_A), key(GLFW_KEY_E) - key(GLFW_KEY_Q),
                             key(GLFW_KEY_S) - key(GLFW_KEY_W));
            const bool fast = key(GLFW_KEY_LEFT_SHIFT) + key(GLFW_KEY_RIGHT_SHIFT) > 0.f;
            move *= float(std::min(seconds, 0.1)) * (fast ? 1.f : 0.25f);
        }
        float yaw = 0.f, pitch = 0.f;
        if (!io.WantCaptureMouse && glfwGetMouseButton(mWindow, GLFW_MOUSE_BUTTON_RIGHT) == GLFW_PRESS) {
            yaw = -0.005f * io.MouseDelta.x;
            pitch = -0.005f * io.MouseDelta.y;
        }
        if (move != glm::vec3(0.f) || yaw != 0.f || pitch != 0.f) act([&] { session.moveCamera(move, yaw, pitch); });
    }

private:
    /// The back buffer as an 8-bit PNG, top row first.
    static void writeFramebuffer(const std::string& path, int width, int height) {
        Texture t(uint32_t(width), uint32_t(height), Format::RGBA8Unorm);
        std::vector<uint8_t> pixels(size_t(width) * size_t(height) * 4);
        glPixelStorei(GL_PACK_ALIGNMENT, 1);
        glReadBuffer(GL_BACK);
        glReadPixels(0, 0, width, height, GL_RGBA, GL_UNSIGNED_BYTE, pixels.data());
        for (int y = 0; y < height; ++y)  // GL's rows run bottom to top
            std::memcpy(t.row(uint32_t(y)), &pixels[size_t(height - 1 - y) * size_t(width) * 4], size_t(width) * 4);
        writeImage(path, t);
    }

    /// The values of the pixel under the mouse, as a tooltip.
    void inspect(const Texture& shown, const ImagePlacement& at, float areaW) {
        const ImGuiIO& io = ImGui::GetIO();
        uint32_t x, y;
        if (io.WantCaptureMouse || io.MousePos.x >= areaW ||
            !at.pixelAt(io.MousePos.x, io.MousePos.y, shown.width(), shown.height(), x, y))
            return;
        ImGui::SetTooltip("(%u, %u)  %s", x, y, pixelText(shown, x, y).c_str());
    }

    /// Zoom and pan of the image while the panel does not want the mouse or keyboard: the wheel zooms about the
    /// mouse, dragging with the left or middle button pans, F fits the image to the area again, 1 shows it at one
    /// screen pixel per pixel, Escape closes the window.
    void navigate(const Texture& shown, float areaW, float areaH) {
        const ImGuiIO& io = ImGui::GetIO();
        const uint32_t w = shown.width(), h = shown.height();
        const bool overImage = !io.WantCaptureMouse && io.MousePos.x >= 0.f && io.MousePos.x < areaW &&
                               io.MousePos.y >= 0.f && io.MousePos.y < areaH;
        if (overImage && io.MouseWheel != 0.f)
            mViewport.zoomAt(std::pow(1.25f, io.MouseWheel), io.MousePos.x, io.MousePos.y, areaW, areaH, w, h);
        if (!io.WantCaptureMouse && (ImGui::IsMouseDragging(ImGuiMouseButton_Left, 0.f) ||
                                     ImGui::IsMouseDragging(ImGuiMouseButton_Middle, 0.f)))
            mViewport.pan(io.MouseDelta.x, io.MouseDelta.y);
        if (io.WantCaptureKeyboard) return;
        if (ImGui::IsKeyPressed(GLFW_KEY_ESCAPE, false)) glfwSetWindowShouldClose(mWindow, GLFW_TRUE);
        if (ImGui::IsKeyPressed(GLFW_KEY_F, false)) mViewport.fit();
        if (ImGui::IsKeyPressed(GLFW_KEY_1, false)) {
            const float sx = overImage ? io.MousePos.x : 0.5f * areaW, sy = overImage ? io.MousePos.y : 0.5f * areaH;
            mViewport.actualSize(sx, sy, areaW, areaH, w, h);
        }
    }

    void panel(ViewSession& session, bool& paused, bool& stepOnce, double renderMs, float x, float height) {
        ImGui::SetNextWindowPos(ImVec2(x, 0.f));
        ImGui::SetNextWindowSize(ImVec2(kPanelWidth, height));
        ImGui::Begin("Loom", nullptr,
                     ImGuiWindowFlags_NoMove | ImGuiWindowFlags_NoResize | ImGuiWindowFlags_NoCollapse);
        ImGui::PushItemWidth(0.5f * kPanelWidth);  // room for the parameters' names beside their widgets
        ImGui::Text("frame %llu  %ux%u  %.1f ms", (unsigned long long)session.frame(), session.width(),
                    session.height(), renderMs);
        if (const std::string accumulated = session.accumulationText(); !accumulated.empty())
            ImGui::Text("%s", accumulated.c_str());
        if (ImGui::Button(paused ? "Run" : "Pause")) paused = !paused;
        ImGui::SameLine();
        if (ImGui::Button("Step")) stepOnce = true;
        ImGui::SameLine();
        if (ImGui::Button("Reset history")) session.resetHistory();
        ImGui::Text("zoom %.3g:1 (wheel; drag pans, F fits, 1 is 1:1)", mShownScale);
        // The field on display: any of the graph's, history included; switching keeps every pass's state.
        if (ImGui::BeginCombo("field", session.viewed().c_str())) {
            for (const std::string& f : session.fields())
                if (ImGui::Selectable(f.c_str(), f == session.viewed())) act([&] { session.view(f); });
            ImGui::EndCombo();
        }
        float ev = session.exposure();
        if (ImGui::SliderFloat("exposure (EV)", &ev, -10.f, 10.f, "%.2f")) act([&] { session.setExposure(ev); });
        if (ImGui::Button("Save field")) act([&] { saveNext(session, true); });
        ImGui::SameLine();
        if (ImGui::Button("Save screen")) act([&] { saveNext(session, false); });
        if (!mMessage.empty()) ImGui::TextWrapped("%s", mMessage.c_str());
        const auto timings = session.graph().timings();
        const auto stats = session.graph().lastStats();
        for (const std::string& name : session.graph().plan().order) {
            const auto t =
                std::find_if(timings.begin(), timings.end(), [&](const PassTiming& p) { return p.name == name; });
            const std::string header =
                fmt::format("{}  {:.2f} ms###{}", name, t == timings.end() ? 0.0 : t->lastMs, name);
            if (mOpenPasses) ImGui::SetNextItemOpen(true, ImGuiCond_Once);
            if (!ImGui::CollapsingHeader(header.c_str())) continue;
            ImGui::PushID(name.c_str());
            RenderPass* pass = session.graph().pass(name);
            for (const ParamDecl& d : pass->params().decls()) {
                const std::string error = paramWidget(session, name, d);
                if (!error.empty()) mMessage = error;
            }
            if (const auto s = stats.find(name); s != stats.end())
                for (const auto& [k, v] : s->second) ImGui::Text("%s: %g", k.c_str(), v);
            ImGui::PopID();
        }
        ImGui::PopItemWidth();
        ImGui::End();
    }

    template <class F>
    void act(F&& f) {
        try {
            f();
            mMessage.clear();
        } catch (const Error& e) {
            mMessage = e.what();
        }
    }

    void saveNext(const ViewSession& session, bool field) {
        std::string name = session.viewed();
        // The field's own values as `loom render --dump` writes them (EXR, or PNG for 8-bit fields); the screen as PNG.
        const char* extension = field ? imageExtension(session.viewedTexture().format()) : "png";
        const std::string path = fmt::format("loom-{}-{:04}.{}", name, session.frame(), extension);
        field ? session.saveField(path) : session.saveDisplay(path);
        mMessage = "saved " + path;
    }

    ImageViewport mViewport;
    float mShownScale = 1.f;  ///< screen pixels per image pixel in the last frame drawn
    bool mOpenPasses = false;
    uint64_t mUploaded = 0;  ///< the display version in the texture
    GLFWwindow* mWindow = nullptr;
    GLuint mTexture = 0;
    std::string mMessage;
};

#endif  // LOOM_HAVE_VIEWER

void runView(const ViewOptions& o) {
    // SIGINT or SIGTERM: the frame under way finishes, then the session ends as when the window closes (the --record
    // video holds the frames recorded, --screenshot is the last frame).
    const StopOnSignal stopOnSignal;
    ViewSession session(o);  // checks the options, then limits the worker threads
    const auto finished = [&] { return (o.frames > 0 && session.frame() >= o.frames) || stopRequested(); };
    if (o.headless) {
        while (!finished()) session.step();
    } else {
#ifdef LOOM_HAVE_VIEWER
        Window window(session);
        bool paused = false, stepOnce = false;
        double renderMs = 0.0;
        auto lastReload = std::chrono::steady_clock::now(), lastLoop = lastReload;
        while (window.open() && !finished()) {
            if (!paused || stepOnce) {
                window.release();
                const auto t0 = std::chrono::steady_clock::now();
                session.step();
                renderMs = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
                stepOnce = false;
            }
            const auto now = std::chrono::steady_clock::now();
            if (now - lastReload > std::chrono::milliseconds(500)) {
                lastReload = now;
                const std::string error = session.reloadIfChanged();
                if (!error.empty()) spdlog::error("{}", error);
            }
            window.draw(session, paused, stepOnce, renderMs, finished() ? o.windowShot : std::string());
            const auto end = std::chrono::steady_clock::now();
            window.steer(session, std::chrono::duration<double>(end - lastLoop).count());
            lastLoop = end;
        }
        // Closed before a last frame: the window as it was when closed.
        if (!finished() && !o.windowShot.empty()) window.draw(session, paused, stepOnce, renderMs, o.windowShot);
#else
        throw Error({ErrorKind::Runtime,
                     {},
                     "loom view",
                     "this build has no window support (GLFW, Dear ImGui)",
                     "",
                     "install libglfw3-dev and libimgui-dev and rebuild, or use --headless"});
#endif
    }
    if (o.headless && session.frame() > 0)
        if (const std::string accumulated = session.accumulationText(); !accumulated.empty())
            spdlog::info("after {} frame(s): {}", session.frame(), accumulated);
    if (stopRequested()) spdlog::warn("stopped by {} after {} frame(s)", signalName(stopSignal()), session.frame());
    session.finish();
    if (!o.screenshot.empty() && session.frame() > 0) session.saveDisplay(o.screenshot);
}

}  // namespace

void addViewCommand(CLI::App& app) {
    auto o = std::make_shared<ViewOptions>();
    CLI::App* cmd = app.add_subcommand("view", "Run a graph in a window: show any field, tune parameters live");
    cmd->add_option("--graph,-g", o->graph, "graph file (.json); reloaded when it changes")->required();
    addSizeOption(cmd, o->size, "640x360");
    cmd->add_option("--field", o->field, "field shown first, Pass.field (default: the first output)");
    cmd->add_option("--exposure", o->exposure, "exposure of float fields on display, in EV")->capture_default_str();
    cmd->add_option("--set", o->set, "set a parameter: Pass.param=value (repeatable)");
    addDeviceOption(cmd, o->device);
    cmd->add_option("--frames,-n", o->frames, "stop after this many frames (0: when the window closes)")
        ->capture_default_str();
    cmd->add_option("--script", o->script, "timed commands, lines 'FRAME VERB [ARG]' (docs/VIEWER.md)");
    cmd->add_option("--record", o->record,
                    "every frame's displayed image: FILE.y4m (a video) or a folder of numbered PNGs");
    cmd->add_option("--screenshot", o->screenshot, "write the displayed image as PNG at the end");
    cmd->add_option("--window-shot", o->windowShot,
                    "write the whole window as PNG after the last frame or when it closes");
    cmd->add_option("--fps", o->fps, "frames per second of the animation clock")->capture_default_str();
    cmd->add_option("--threads", o->threads, "worker threads (0 = all cores)")->capture_default_str();
    cmd->add_flag("--open-passes", o->openPasses, "start with every pass's section of the panel open");
    cmd->add_flag("--headless", o->headless, "no window: run --frames frames (with --script, --record, --screenshot)");
    addSceneOptions(cmd, o->scene);
    cmd->callback([o, cmd] {
        o->sizeGiven = cmd->count("--size") > 0;
        runView(*o);
    });
}

}  // namespace loom::cli
