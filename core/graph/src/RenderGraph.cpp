#include "loom/RenderGraph.h"

#include <fnmatch.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cstdlib>
#include <cstring>
#include <deque>
#include <map>
#include <set>
#include <sstream>
#include <unordered_map>

#include "loom/Error.h"
#include "loom/GraphPlanner.h"
#include "loom/PageMemory.h"

namespace loom {

using json = nlohmann::json;

const char* notRunKindName(NotRunKind kind) {
    switch (kind) {
        case NotRunKind::Culled:
            return "culled";
        case NotRunKind::NotComputed:
            return "not computed";
        case NotRunKind::NotConnected:
            return "not connected";
        case NotRunKind::NotAllocated:
            return "not allocated";
    }
    return "?";
}

bool globMatch(const std::string& pattern, const std::string& text) {
    return fnmatch(pattern.c_str(), text.c_str(), 0) == 0;
}

namespace {

/// Memory for transient fields: PageMemory, which the kernel zeroes lazily and
/// backs with huge pages where it can, so a large arena costs nothing until
/// touched; a recompile that fits in the current arena keeps it.
class Arena {
public:
    bool reserve(size_t bytes) {
        if (bytes <= mMemory.size() && bytes * 2 >= mMemory.size()) return true;
        mMemory.release();
        if (bytes == 0) return true;
        try {
            mMemory = PageMemory(bytes);
        } catch (const std::bad_alloc&) {
            return false;
        }
        return true;
    }
    std::byte* data() const { return mMemory.data(); }

private:
    PageMemory mMemory;
};

std::string bytesText(size_t bytes) {
    if (bytes >= (size_t(1) << 20)) return fmt::format("{:.2f} MiB", bytes / double(1 << 20));
    if (bytes >= 1024) return fmt::format("{:.1f} KiB", bytes / 1024.0);
    return fmt::format("{} B", bytes);
}

}  // namespace

struct HistoryEntry {
    std::string key;
    std::string passType;
    Format format = Format::RGBA32F;
    uint32_t width = 0, height = 0;
    bool inPlace = false;  // one texture: prev views cur's memory, and there is nothing to swap
    Texture cur, prev;
    bool valid = false;        // prev holds a real frame
    bool pendingSwap = false;  // cur was written by the last frame
};

struct PassNode {
    PassDesc desc;
    std::unique_ptr<RenderPass> pass;
    Reflection refl;
    bool live = false;
    int position = -1;
    CompileInfo info;
    PassContext ctx;
    PassTiming timing;
    Stats stats;
    std::vector<std::string> observeBefore;  // inputs
    std::vector<std::string> observeAfter;   // outputs, internals, history
    std::vector<Texture*> poisonAtStart;     // transients whose lifetime starts here
    DeviceKind device = DeviceKind::Cpu;     // where it runs
    std::vector<std::pair<Texture*, const Texture*>> copiesBefore;  // (to, from): inputs from another device
    std::vector<std::pair<Texture*, const Texture*>> copiesAfter;   // (host copy, field): outputs off the host
    std::vector<const bool*> validFlags;     // history validity this pass depends on
    std::vector<PassNode*> sources;          // the passes whose outputs it reads (this frame's or @prev)
    bool paramsChanged = true;               // a parameter that counts changed value since the last frame
};

struct RenderGraph::Impl {
    GraphDesc desc;
    PluginRegistry& registry;
    std::shared_ptr<const Scene> scene;
    std::vector<std::unique_ptr<PassNode>> nodes;  // in description order
    std::vector<PassNode*> order;                  // live, in execution order
    std::map<std::string, std::unique_ptr<HistoryEntry>> history;
    Arena arena;                                   // the host's transients
    std::shared_ptr<std::byte> deviceArenas[3];    // the other devices' transients (by DeviceKind)
    size_t deviceArenaBytes[3] = {0, 0, 0};
    std::vector<std::unique_ptr<Texture>> transients;
    std::map<std::string, Texture*> fieldTextures;
    std::map<std::string, Texture> hostCopies;     // host copies of marked or observed fields off the host

    Impl(GraphDesc d, PluginRegistry& r) : desc(std::move(d)), registry(r) {}

    std::unordered_map<std::string, PassNode*> byName;

    PassNode* node(const std::string& name) const {
        auto it = byName.find(name);
        return it == byName.end() ? nullptr : it->second;
    }
    void indexNodes() {
        byName.clear();
        for (const auto& n : nodes) byName.emplace(n->desc.name, n.get());
    }
    std::vector<std::string> passNames() const {
        std::vector<std::string> out;
        for (const auto& n : nodes) out.push_back(n->desc.name);
        return out;
    }
    std::unique_ptr<PassNode> makeNode(const PassDesc& pd, size_t index) const;
    void allocate(const CompiledPlan& plan, const std::string& file);
    void bind(GraphPlan& plan);
    std::byte* arenaBase(DeviceKind device, size_t bytes);
    void place(const CompileOptions& options, std::vector<DeviceKind>& devices, std::vector<std::string>& notes) const;
};

std::unique_ptr<PassNode> RenderGraph::Impl::makeNode(const PassDesc& pd, size_t index) const {
    auto n = std::make_unique<PassNode>();
    n->desc = pd;
    const std::string file = desc.file.string();
    try {
        n->pass = registry.create(pd.type);
    } catch (const Error& e) {
        Error::Info info = e.info();
        if (info.where.empty()) info.where = fmt::format("/passes/{}/type", index);
        if (info.file.empty() || info.kind == ErrorKind::BadInput) {
            // Name the graph; keep a plugin library's path in the message.
            if (!info.file.empty()) info.what = info.file + ": " + info.what;
            info.file = file;
        }
        throw Error(std::move(info));
    }
    try {
        n->pass->params().setAll(pd.params, fmt::format("/passes/{}/params", index));
    } catch (const Error& e) {
        throw e.withFile(file);
    }
    n->timing.name = pd.name;
    if (scene) n->pass->setScene(scene);
    return n;
}

/// Where each pass runs: its own "device", else --device (CompileOptions::device), else the graph's; auto is CUDA
/// where a usable GPU is present, else the CPU. A pass without a version for the device asked for runs on the CPU
/// (the note says so, and the plan's transfers what it costs). Cuda without a usable GPU is bad input, except when
/// only planning.
void RenderGraph::Impl::place(const CompileOptions& options, std::vector<DeviceKind>& devices,
                              std::vector<std::string>& notes) const {
    if (!options.device.empty() && !parseDeviceKind(options.device) && options.device != "auto")
        throwBadInput("--device", "unknown device '" + options.device + "'", "one of: " + join(deviceChoices()),
                      didYouMean(options.device, deviceChoices(), ""));
    devices.assign(nodes.size(), DeviceKind::Cpu);
    notes.assign(nodes.size(), std::string());
    for (size_t i = 0; i < nodes.size(); ++i) {
        const PassNode& n = *nodes[i];
        const std::string& asked = !n.desc.device.empty()  ? n.desc.device
                                   : !options.device.empty() ? options.device
                                                             : desc.device;
        DeviceKind d = DeviceKind::Cpu;
        if (asked.empty() || asked == "auto") {
            d = cudaStatus().usable ? DeviceKind::Cuda : DeviceKind::Cpu;
        } else {
            d = *parseDeviceKind(asked);
            if (d == DeviceKind::Cuda && !cudaStatus().usable && !options.planOnly)
                throw Error(Error::Info{ErrorKind::BadInput, desc.file.string(), n.desc.name + ".device",
                                        "device 'cuda' was asked for, and " + cudaStatus().description,
                                        "a usable NVIDIA GPU with its driver, in a build with CUDA support",
                                        "use device auto (CUDA where usable, else the CPU), cpu or emulated"});
        }
        if (d != DeviceKind::Cpu && !n.pass->runsOn(d)) {
            notes[i] = fmt::format("{} has no {} version: runs on the CPU", n.desc.type, deviceName(d));
            d = DeviceKind::Cpu;
        }
        devices[i] = d;
    }
}

/// The transient arena of a device other than the host, grown to `bytes` (and kept while it fits).
std::byte* RenderGraph::Impl::arenaBase(DeviceKind device, size_t bytes) {
    const size_t d = size_t(device);
    if (bytes > deviceArenaBytes[d] || bytes * 2 < deviceArenaBytes[d]) {
        deviceArenas[d].reset();
        deviceArenaBytes[d] = 0;
        if (bytes > 0)
            deviceArenas[d] = allocateOnDevice(device, bytes, fmt::format("the {} transient arena", deviceName(device)));
        deviceArenaBytes[d] = bytes;
    }
    return deviceArenas[d].get();
}

/// The arena for the plan's transients, and its history pairs (kept when their declaration is unchanged), on each
/// device; host copies of the fields that leave a device.
void RenderGraph::Impl::allocate(const CompiledPlan& plan, const std::string& file) {
    transients.clear();
    fieldTextures.clear();
    hostCopies.clear();
    if (!arena.reserve(plan.devicePeakBytes[size_t(DeviceKind::Cpu)]))
        throw Error(Error::Info{ErrorKind::Runtime,
                                file,
                                {},
                                "out of memory for " + bytesText(plan.transientPeakBytes) + " of frame data",
                                {},
                                "render at a smaller size"});
    std::byte* bases[3] = {arena.data(), nullptr, nullptr};
    for (DeviceKind d : {DeviceKind::Cuda, DeviceKind::Emulated})
        bases[size_t(d)] = arenaBase(d, plan.devicePeakBytes[size_t(d)]);
    std::set<std::string> historyKeys;
    for (const ResourceInfo& r : plan.resources) {
        if (r.kind == ResourceKind::Transient) {
            auto tex = std::make_unique<Texture>(
                Texture::wrap(bases[size_t(r.device)] + r.offset, r.width, r.height, r.format, r.device));
            fieldTextures[r.name] = tex.get();
            transients.push_back(std::move(tex));
        } else {
            historyKeys.insert(r.name);
        }
    }
    for (auto it = history.begin(); it != history.end();) {
        if (!historyKeys.count(it->first)) {
            it = history.erase(it);
        } else {
            ++it;
        }
    }
    for (const ResourceInfo& r : plan.resources) {
        if (r.kind != ResourceKind::History) continue;
        const std::string& type = desc.passes[r.pass].type;
        auto& entry = history[r.name];
        if (!entry || entry->passType != type || entry->format != r.format || entry->width != r.width ||
            entry->height != r.height || entry->cur.residence() != r.device || entry->inPlace != r.inPlace) {
            entry = std::make_unique<HistoryEntry>();
            entry->key = r.name;
            entry->passType = type;
            entry->format = r.format;
            entry->width = r.width;
            entry->height = r.height;
            entry->inPlace = r.inPlace;
            entry->cur = Texture::onDevice(r.device, r.width, r.height, r.format, r.name);
            entry->prev = r.inPlace ? Texture::wrap(entry->cur.data(), r.width, r.height, r.format, r.device)
                                    : Texture::onDevice(r.device, r.width, r.height, r.format, r.name);
        }
        fieldTextures[r.name] = &entry->cur;
    }
}

/// Binds each live pass's context to the plan's textures, and compiles the pass.
void RenderGraph::Impl::bind(GraphPlan& plan) {
    for (size_t i = 0; i < nodes.size(); ++i) {
        PassNode& n = *nodes[i];
        PassPlan& pp = plan.passes[i];
        n.ctx = PassContext();
        n.observeBefore.clear();
        n.observeAfter.clear();
        n.poisonAtStart.clear();
        n.validFlags.clear();
        n.sources.clear();
        n.copiesBefore.clear();
        n.copiesAfter.clear();
        n.live = pp.live;
        n.position = pp.position;
        n.device = pp.device;
        n.refl = std::move(pp.reflection);
        if (!n.live) continue;
        n.ctx.mPassName = n.desc.name;
        n.ctx.mDevice = pp.device;
        n.ctx.mStats = &n.stats;
        const std::set<std::string> observed(pp.observed.begin(), pp.observed.end());
        for (const auto& f : n.refl.fields()) {
            const std::string key = fieldKey(n.desc.name, f.name);
            BoundField b{f.name, f.kind};
            if (f.kind == FieldKind::Input) {
                auto in = std::find_if(pp.inputs.begin(), pp.inputs.end(),
                                       [&](const PlannedInput& p) { return p.field == f.name; });
                if (in != pp.inputs.end()) {
                    if (in->srcPass != i) n.sources.push_back(nodes[in->srcPass].get());
                    const std::string srcKey = fieldKey(desc.passes[in->srcPass].name, in->srcField);
                    if (in->prev) {
                        HistoryEntry& e = *history.at(srcKey);
                        b.cur = &e.prev;
                        b.valid = &e.valid;
                        n.validFlags.push_back(&e.valid);
                    } else {
                        b.cur = fieldTextures.at(srcKey);
                    }
                    if (in->transfer >= 0) {  // the source lives on another device: read its copy here
                        const TransferInfo& t = plan.summary.transfers[size_t(in->transfer)];
                        Texture* copy = fieldTextures.at(t.resource);
                        if (t.position == n.position) n.copiesBefore.emplace_back(copy, b.cur);
                        b.cur = copy;
                    }
                }
            } else if (f.kind == FieldKind::History || (f.kind == FieldKind::Output && history.count(key))) {
                HistoryEntry& e = *history.at(key);
                b.cur = &e.cur;
                b.prev = &e.prev;
                b.valid = &e.valid;
                if (f.kind == FieldKind::History) n.validFlags.push_back(&e.valid);
            } else if (auto it = fieldTextures.find(key); it != fieldTextures.end()) {
                b.cur = it->second;
                n.poisonAtStart.push_back(it->second);
            }
            if (observed.count(f.name) && b.cur)
                (f.kind == FieldKind::Input ? n.observeBefore : n.observeAfter).push_back(f.name);
            n.ctx.mFields.push_back(b);
        }
        for (const TransferInfo& t : plan.summary.transfers)
            if (t.after && t.position == n.position) {
                const std::string field = t.field.substr(n.desc.name.size() + 1);
                for (const BoundField& b : n.ctx.mFields)
                    if (b.name == field && b.cur) {
                        auto [copy, _] = hostCopies.try_emplace(
                            t.field, Texture(b.cur->width(), b.cur->height(), b.cur->format()));
                        n.copiesAfter.emplace_back(&copy->second, b.cur);
                    }
            }
        n.info = pp.info;
        n.pass->compile(n.info);
    }
}

RenderGraph::RenderGraph(GraphDesc desc, PluginRegistry& registry)
    : mImpl(std::make_unique<Impl>(std::move(desc), registry)) {
    for (size_t i = 0; i < mImpl->desc.passes.size(); ++i)
        mImpl->nodes.push_back(mImpl->makeNode(mImpl->desc.passes[i], i));
    mImpl->indexNodes();
}

RenderGraph::~RenderGraph() = default;

RenderPass* RenderGraph::pass(const std::string& name) const {
    PassNode* n = mImpl->node(name);
    return n ? n->pass.get() : nullptr;
}

void RenderGraph::setDesc(GraphDesc desc) {
    auto next = std::make_unique<Impl>(std::move(desc), mImpl->registry);
    next->scene = mImpl->scene;
    const size_t count = next->desc.passes.size();
    // Create the new passes and set the kept ones' parameters before taking any node from the current graph,
    // so an unknown type or a bad parameter leaves the graph as it was.
    std::vector<std::unique_ptr<PassNode>> nodes(count);
    std::vector<std::unique_ptr<PassNode>*> kept(count, nullptr);
    std::unordered_map<std::string, std::unique_ptr<PassNode>*> old;  // pass names are unique
    for (auto& n : mImpl->nodes) old.emplace(n->desc.name, &n);
    for (size_t i = 0; i < count; ++i) {
        const PassDesc& pd = next->desc.passes[i];
        if (auto it = old.find(pd.name); it != old.end() && (*it->second)->desc.type == pd.type) kept[i] = it->second;
        if (!kept[i]) nodes[i] = next->makeNode(pd, i);
    }
    for (size_t i = 0; i < count; ++i)
        if (kept[i])
            (*kept[i])->pass->params().setAll(next->desc.passes[i].params, fmt::format("/passes/{}/params", i));
    for (size_t i = 0; i < count; ++i) {
        if (!kept[i]) continue;
        nodes[i] = std::move(*kept[i]);
        nodes[i]->desc = next->desc.passes[i];
    }
    mImpl->desc = next->desc;
    mImpl->nodes = std::move(nodes);
    mImpl->indexNodes();
    // Kept passes may have new parameters or new wiring: every pass's consumers see a change.
    for (auto& n : mImpl->nodes) n->paramsChanged = true;
    // Dropped passes are destroyed: the old plan must never run again.
    mCompiled = false;
    mImpl->order.clear();
    compile(mOptions);
}

void RenderGraph::setScene(std::shared_ptr<const Scene> scene) {
    mImpl->scene = std::move(scene);
    for (auto& n : mImpl->nodes) n->pass->setScene(mImpl->scene);
    resetHistory();
}

void RenderGraph::resize(uint32_t width, uint32_t height) {
    if (width == mOptions.width && height == mOptions.height && mCompiled) return;
    CompileOptions o = mOptions;
    o.width = width;
    o.height = height;
    compile(o);
    resetHistory();  // even history of fixed-size fields: a new frame size is a new sequence
}

void RenderGraph::setParam(const std::string& passName, const std::string& param, const json& value,
                           const std::string& where) {
    PassNode* n = mImpl->node(passName);
    if (!n)
        throwBadInput(where, "unknown pass '" + passName + "'", "one of: " + join(mImpl->passNames()),
                      didYouMean(passName, mImpl->passNames(), ""));
    ParamList& params = n->pass->params();
    const ParamDecl* decl = params.find(param);
    const json before = decl ? decl->get() : json();
    params.set(param, value, where);
    // A new seed or sample count changes the noise, not the image the samples estimate (see inputParamsChanged).
    if (decl && decl->role != ParamRole::Seed && decl->role != ParamRole::SampleCount && decl->get() != before)
        n->paramsChanged = true;
}

GraphDesc RenderGraph::desc() const {
    GraphDesc d = mImpl->desc;
    for (size_t i = 0; i < d.passes.size(); ++i) {
        PassNode* n = mImpl->node(d.passes[i].name);
        if (n) d.passes[i].params = n->pass->params().toJson(true);
    }
    return d;
}

std::optional<NaturalSize> RenderGraph::naturalSize() const {
    std::optional<NaturalSize> found;
    for (const auto& n : mImpl->nodes) {
        std::optional<glm::uvec2> size;
        try {
            size = n->pass->naturalSize();
        } catch (const Error& e) {
            // A pass names its parameters by its type; the graph knows it by its name.
            Error::Info info = e.info();
            const std::string& type = n->desc.type;
            if (info.where.compare(0, type.size(), type) == 0 &&
                (info.where.size() == type.size() || info.where[type.size()] == '.'))
                info.where = n->desc.name + info.where.substr(type.size());
            if (info.where.empty()) info.where = n->desc.name;
            throw Error(info);
        }
        if (!size) continue;
        if (size->x == 0 || size->y == 0 || size->x > 16384 || size->y > 16384)
            throwBadInput(n->desc.name, fmt::format("its data is {}x{}", size->x, size->y),
                          "a frame size from 1x1 to 16384x16384", "", mImpl->desc.file.string());
        if (found && (found->width != size->x || found->height != size->y))
            throwBadInput(n->desc.name,
                          fmt::format("the sources disagree on the frame size: {} is {}x{}, {} is {}x{}", found->pass,
                                      found->width, found->height, n->desc.name, size->x, size->y),
                          "sources of one size", "point the sources at frames of one size",
                          mImpl->desc.file.string());
        if (!found) found = NaturalSize{size->x, size->y, n->desc.name};
    }
    return found;
}

void RenderGraph::compile(const CompileOptions& options) {
    Impl& m = *mImpl;
    const std::string file = m.desc.file.string();
    if (options.width == 0 || options.height == 0 || options.width > 16384 || options.height > 16384)
        throwBadInput("size", fmt::format("frame size {}x{} is not allowed", options.width, options.height),
                      "a size between 1x1 and 16384x16384");

    // Reflect every pass, then plan: wiring, culling, order, second reflections, lifetimes, arena placement.
    PlannerInput input;
    input.desc = &m.desc;
    input.width = options.width;
    input.height = options.height;
    input.observe = options.observe;
    for (auto& n : m.nodes) {
        CompileInfo info;
        info.frameWidth = options.width;
        info.frameHeight = options.height;
        n->pass->reflect(input.reflections.emplace_back(), info);
    }
    input.reflectWired = [&](size_t pass, const CompileInfo& info) {
        Reflection wired;
        m.nodes[pass]->pass->reflect(wired, info);
        return wired;
    };
    m.place(options, input.devices, input.deviceNotes);
    GraphPlan graphPlan = planGraph(input);
    planResources(graphPlan, m.desc);
    CompiledPlan& plan = graphPlan.summary;
    if (options.planOnly) {  // loom check: the plan, with nothing allocated or compiled
        mCompiled = false;
        m.order.clear();
        mPlan = std::move(plan);
        mOptions = options;
        return;
    }

    // The old plan's memory is released first, so until this compile succeeds there is no plan to execute.
    mCompiled = false;
    m.order.clear();
    m.allocate(plan, file);
    m.bind(graphPlan);
    for (uint32_t p : graphPlan.order) m.order.push_back(m.nodes[p].get());
    mPlan = std::move(plan);
    mOptions = options;
    mCompiled = true;
    for (const auto& w : mPlan.warnings) spdlog::warn("{}", w);
}

void RenderGraph::execute(const FrameInfo& frame) {
    if (mOptions.planOnly)
        throw Error(Error::Info{ErrorKind::Runtime, {}, {}, "the graph was compiled to plan only, not to run",
                                "a compile without planOnly", {}});
    if (!mCompiled) compile(mOptions);
    Impl& m = *mImpl;
    // Last frame's "cur" becomes this frame's "prev" (a swap, no copy).
    for (auto& [_, e] : m.history) {
        if (e->pendingSwap) {
            if (!e->inPlace) std::swap(e->cur, e->prev);
            e->valid = true;
            e->pendingSwap = false;
        }
    }
    // Which passes read, directly or through others, from a pass whose parameters changed: iterated to a fixed
    // point, since an @prev edge may come from a pass later in the order.
    for (PassNode* n : m.order) n->ctx.mInputParamsChanged = false;
    for (bool grew = true; grew;) {
        grew = false;
        for (PassNode* n : m.order)
            for (const PassNode* s : n->sources)
                if (!n->ctx.mInputParamsChanged && (s->paramsChanged || s->ctx.mInputParamsChanged))
                    n->ctx.mInputParamsChanged = grew = true;
    }
    for (PassNode* n : m.order) {
        if (mOptions.poisonTransients)
            for (Texture* t : n->poisonAtStart) t->poison();
        PassContext& ctx = n->ctx;
        ctx.mFrameIndex = frame.frameIndex;
        ctx.mTime = frame.time;
        ctx.mFrameWidth = mOptions.width;
        ctx.mFrameHeight = mOptions.height;
        ctx.mScene = frame.scene;
        ctx.mCamera = frame.camera;
        ctx.mHistoryValid = true;
        for (const bool* v : n->validFlags) ctx.mHistoryValid = ctx.mHistoryValid && *v;
        for (const auto& [to, from] : n->copiesBefore) copyTexture(*to, *from);
        const bool onHost = n->device == DeviceKind::Cpu;
        if (mObserver && onHost)
            for (const auto& name : n->observeBefore) mObserver(frame, n->desc.name, name, *ctx.input(name));
        n->stats.clear();
        auto t0 = std::chrono::steady_clock::now();
        try {
            n->pass->execute(ctx);
        } catch (const Error& e) {
            if (!e.info().where.empty() && e.info().where != "device") throw;
            Error::Info info = e.info();  // a device's failure: name the pass it failed in
            info.where = n->desc.name;
            throw Error(std::move(info));
        } catch (const std::bad_alloc&) {
            throw;
        } catch (const std::exception& e) {
            throw Error(
                Error::Info{ErrorKind::Runtime, {}, n->desc.name, std::string("pass failed: ") + e.what(), {}, {}});
        } catch (...) {
            // A plugin may throw anything; it must not abort the process.
            throw Error(Error::Info{ErrorKind::Runtime,
                                    {},
                                    n->desc.name,
                                    "pass failed with an exception that is not a std::exception",
                                    {},
                                    "report it to the plugin's author"});
        }
        auto t1 = std::chrono::steady_clock::now();
        double ms = std::chrono::duration<double, std::milli>(t1 - t0).count();
        n->timing.lastMs = ms;
        n->timing.totalMs += ms;
        ++n->timing.runs;
        for (const auto& [to, from] : n->copiesAfter) copyTexture(*to, *from);
        if (mObserver) {
            // Off the host, the observer sees the host copies (inputs too, which the pass does not change).
            const auto shown = [&](const std::string& name, const Texture& t) -> const Texture& {
                if (onHost) return t;
                return mImpl->hostCopies.at(fieldKey(n->desc.name, name));
            };
            if (!onHost)
                for (const auto& name : n->observeBefore) mObserver(frame, n->desc.name, name, shown(name, *ctx.input(name)));
            for (const auto& name : n->observeAfter)
                for (const auto& b : ctx.mFields)
                    if (b.name == name && b.kind != FieldKind::Input)
                        mObserver(frame, n->desc.name, name, shown(name, *b.cur));
        }
    }
    for (auto& [_, e] : m.history) e->pendingSwap = true;
    for (auto& n : m.nodes) n->paramsChanged = false;
}

void RenderGraph::resetHistory() {
    for (auto& [_, e] : mImpl->history) {
        e->cur.clear();
        e->prev.clear();
        e->valid = false;
        e->pendingSwap = false;
    }
    for (auto& n : mImpl->nodes) n->pass->resetHistory();
}

const Texture* RenderGraph::fieldTexture(const std::string& passDotField) const {
    if (auto copy = mImpl->hostCopies.find(passDotField); copy != mImpl->hostCopies.end()) return &copy->second;
    auto it = mImpl->fieldTextures.find(passDotField);
    return it == mImpl->fieldTextures.end() ? nullptr : it->second;
}

std::vector<PassTiming> RenderGraph::timings() const {
    std::vector<PassTiming> out;
    for (auto* n : mImpl->order) out.push_back(n->timing);
    return out;
}

std::map<std::string, std::map<std::string, double>> RenderGraph::lastStats() const {
    std::map<std::string, std::map<std::string, double>> out;
    for (auto* n : mImpl->order)
        if (!n->stats.values().empty()) out[n->desc.name] = n->stats.values();
    return out;
}

std::string RenderGraph::planText() const {
    const CompiledPlan& p = mPlan;
    std::ostringstream s;
    s << "Graph '" << mImpl->desc.name << "'";
    if (!mImpl->desc.file.empty()) s << " (" << mImpl->desc.file.string() << ")";
    s << ", " << p.width << "x" << p.height << "\n\nExecution order:\n";
    for (size_t i = 0; i < p.order.size(); ++i)
        s << fmt::format("  {:2}. {} ({})\n", i + 1, p.order[i], mImpl->node(p.order[i])->desc.type);
    s << "\nWiring:\n";
    for (const auto& w : p.wires)
        s << "  " << w.src.str() << " -> " << w.dst.str() << (w.byName ? "   (by name)" : "") << "\n";
    s << "\nMarked outputs:\n";
    for (const auto& o : p.outputs) s << "  " << o.str() << "\n";
    // What the planner leaves out, then what each live pass leaves out of its work for the scene.
    std::vector<std::string> notRun;
    for (const NotRun& n : p.notRun)
        notRun.push_back(fmt::format("{} ({}): {}", n.field.empty() ? n.pass : fieldKey(n.pass, n.field),
                                     notRunKindName(n.kind), n.reason));
    if (mImpl->scene)
        for (const PassNode* n : mImpl->order)
            for (const std::string& line : n->pass->skippedWork()) notRun.push_back(n->desc.name + ": " + line);
    s << "\nNot run or not allocated, and why:" << (notRun.empty() ? " none\n" : "\n");
    for (const std::string& line : notRun) s << "  " << line << "\n";
    s << "\nAllocations:\n";
    for (const auto& r : p.resources) {
        s << fmt::format("  {:28} {:10} {:>5}x{:<5} {:>11}  ", r.name, formatName(r.format), r.width, r.height,
                         bytesText(r.bytes));
        if (r.kind == ResourceKind::History)
            s << (r.inPlace ? "history, updated in place (1 texture)\n" : "history pair (2 textures)\n");
        else
            s << fmt::format("transient, passes {}..{}, offset {}\n", r.firstUse + 1,
                             r.lastUse >= int(p.order.size()) ? std::string("end") : std::to_string(r.lastUse + 1),
                             bytesText(r.offset));
    }
    s << "\nDevices:\n";
    for (const PlacedPass& pp : p.placement)
        s << fmt::format("  {:28} {}{}\n", pp.name, deviceName(pp.device), pp.note.empty() ? "" : "   (" + pp.note + ")");
    size_t perFrame = 0;
    for (const TransferInfo& t : p.transfers) perFrame += t.bytes;
    s << "\nTransfers per frame:" << (p.transfers.empty() ? " none\n" : fmt::format(" {}\n", bytesText(perFrame)));
    for (const TransferInfo& t : p.transfers)
        s << fmt::format("  {:34} {:>8} -> {:<8} {:>11}  {} {} ({})\n", t.field, deviceName(t.from), deviceName(t.to),
                         bytesText(t.bytes), t.after ? "after" : "before",
                         t.position < int(p.order.size()) ? p.order[size_t(t.position)] : std::string("?"), t.reason);
    double saved = p.transientSumBytes ? 100.0 * (1.0 - double(p.transientPeakBytes) / p.transientSumBytes) : 0.0;
    const double pixels = double(std::max<uint64_t>(uint64_t(p.width) * p.height, 1));
    s << fmt::format("\nMemory: transient arena {} (unshared {}, {:.0f}% saved); history {}; peak {} ({:.0f} bytes a "
                     "pixel)\n",
                     bytesText(p.transientPeakBytes), bytesText(p.transientSumBytes), saved, bytesText(p.historyBytes),
                     bytesText(p.transientPeakBytes + p.historyBytes),
                     double(p.transientPeakBytes + p.historyBytes) / pixels);
    for (DeviceKind d : {DeviceKind::Cpu, DeviceKind::Cuda, DeviceKind::Emulated}) {
        const size_t arenaBytes = p.devicePeakBytes[size_t(d)], historyBytes = p.deviceHistoryBytes[size_t(d)];
        if (arenaBytes + historyBytes == 0) continue;
        s << fmt::format("  on {:8}: transient arena {}, history {}, peak {}\n", deviceName(d), bytesText(arenaBytes),
                         bytesText(historyBytes), bytesText(arenaBytes + historyBytes));
    }
    for (const auto& w : p.warnings) s << "warning: " << w << "\n";
    return s.str();
}

std::string RenderGraph::planDot() const {
    const CompiledPlan& p = mPlan;
    std::ostringstream s;
    s << "digraph \"" << mImpl->desc.name << "\" {\n  rankdir=LR;\n  node [shape=record, fontname=\"Helvetica\"];\n";
    for (const auto& n : mImpl->nodes) {
        std::vector<std::string> ins, outs;
        for (const auto& f : n->refl.fields()) {
            std::string port = "<" + f.name + "> " + f.name;
            if (f.kind == FieldKind::Input) ins.push_back(port);
            if (f.kind == FieldKind::Output) outs.push_back(port);
            if (f.kind == FieldKind::History) outs.push_back("<" + f.name + "> " + f.name + " (history)");
        }
        s << "  \"" << n->desc.name << "\" [label=\"{{" << join(ins, "|") << "}|" << n->desc.name << "\\n("
          << n->desc.type << ")|{" << join(outs, "|") << "}}\"" << (n->live ? "" : ", style=dashed, color=gray")
          << "];\n";
    }
    for (const auto& w : p.wires)
        s << "  \"" << w.src.pass << "\":\"" << w.src.channel << "\" -> \"" << w.dst.pass << "\":\"" << w.dst.channel
          << "\"" << (w.src.prev ? " [style=dashed, label=\"@prev\"]" : "") << ";\n";
    for (const auto& o : p.outputs) {
        s << "  \"out:" << o.str() << "\" [shape=oval, label=\"" << o.str() << "\"];\n";
        s << "  \"" << o.pass << "\":\"" << o.channel << "\" -> \"out:" << o.str() << "\";\n";
    }
    s << "}\n";
    return s.str();
}

}  // namespace loom
