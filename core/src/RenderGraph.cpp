#include "loom/RenderGraph.h"

#include <fnmatch.h>

#include <algorithm>
#include <cstdlib>
#include <cstring>
#include <deque>
#include <map>
#include <set>
#include <sstream>

#include <spdlog/spdlog.h>

#include "loom/Error.h"
#include "loom/PageMemory.h"

namespace loom {

using json = nlohmann::json;

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

std::string fieldKey(const std::string& pass, const std::string& field) { return pass + "." + field; }

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
    std::vector<const bool*> validFlags;     // history validity this pass depends on
};

struct RenderGraph::Impl {
    GraphDesc desc;
    PluginRegistry& registry;
    std::shared_ptr<const Scene> scene;
    std::vector<std::unique_ptr<PassNode>> nodes;  // in description order
    std::vector<PassNode*> order;                  // live, in execution order
    std::map<std::string, std::unique_ptr<HistoryEntry>> history;
    Arena arena;
    std::vector<std::unique_ptr<Texture>> transients;
    std::map<std::string, Texture*> fieldTextures;

    Impl(GraphDesc d, PluginRegistry& r) : desc(std::move(d)), registry(r) {}

    PassNode* node(const std::string& name) const {
        for (const auto& n : nodes)
            if (n->desc.name == name) return n.get();
        return nullptr;
    }
    std::vector<std::string> passNames() const {
        std::vector<std::string> out;
        for (const auto& n : nodes) out.push_back(n->desc.name);
        return out;
    }
    std::unique_ptr<PassNode> makeNode(const PassDesc& pd, size_t index) const;
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

RenderGraph::RenderGraph(GraphDesc desc, PluginRegistry& registry)
    : mImpl(std::make_unique<Impl>(std::move(desc), registry)) {
    for (size_t i = 0; i < mImpl->desc.passes.size(); ++i)
        mImpl->nodes.push_back(mImpl->makeNode(mImpl->desc.passes[i], i));
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
    for (size_t i = 0; i < count; ++i) {
        const PassDesc& pd = next->desc.passes[i];
        for (auto& old : mImpl->nodes)
            if (old->desc.name == pd.name && old->desc.type == pd.type &&
                std::find(kept.begin(), kept.end(), &old) == kept.end())
                kept[i] = &old;
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
    n->pass->params().set(param, value, where);
}

GraphDesc RenderGraph::desc() const {
    GraphDesc d = mImpl->desc;
    for (size_t i = 0; i < d.passes.size(); ++i) {
        PassNode* n = mImpl->node(d.passes[i].name);
        if (n) d.passes[i].params = n->pass->params().toJson(true);
    }
    return d;
}

namespace {

/// A pass's reflection must name each field once.
void checkUniqueFields(const Reflection& r, const PassDesc& pass) {
    std::set<std::string> seen;
    for (const auto& f : r.fields())
        if (!seen.insert(f.name).second)
            throw Error(Error::Info{ErrorKind::Runtime, {}, fieldKey(pass.name, f.name),
                                    "pass type '" + pass.type + "' declares field '" + f.name + "' twice",
                                    "unique field names", "fix the pass's reflect()"});
}

/// The inputs and outputs of a reflection, in declaration order.
std::vector<FieldDesc> portsOf(const Reflection& r) {
    std::vector<FieldDesc> ports;
    for (const auto& f : r.fields())
        if (f.kind == FieldKind::Input || f.kind == FieldKind::Output) ports.push_back(f);
    return ports;
}

}  // namespace

void RenderGraph::compile(const CompileOptions& options) {
    Impl& m = *mImpl;
    const std::string file = m.desc.file.string();
    auto fail = [&](std::string where, std::string what, std::string expected = {}, std::string hint = {}) {
        throwBadInput(std::move(where), std::move(what), std::move(expected), std::move(hint), file);
    };
    if (options.width == 0 || options.height == 0 || options.width > 16384 || options.height > 16384)
        throwBadInput("size", fmt::format("frame size {}x{} is not allowed", options.width, options.height),
                      "a size between 1x1 and 16384x16384");

    CompiledPlan plan;
    plan.width = options.width;
    plan.height = options.height;

    // 1. Reflect every pass.
    for (auto& n : m.nodes) {
        n->refl = Reflection();
        CompileInfo info;
        info.frameWidth = options.width;
        info.frameHeight = options.height;
        n->pass->reflect(n->refl, info);
        checkUniqueFields(n->refl, n->desc);
    }

    auto fieldNames = [](const PassNode& n, FieldKind kind) { return n.refl.names(kind); };
    auto resolvePass = [&](const ChannelRef& r, const std::string& where) -> PassNode* {
        PassNode* n = m.node(r.pass);
        if (!n)
            fail(where, "unknown pass '" + r.pass + "' in '" + r.str() + "'", "one of: " + join(m.passNames()),
                 didYouMean(r.pass, m.passNames(), ""));
        return n;
    };
    auto resolveField = [&](PassNode& n, const ChannelRef& r, FieldKind kind,
                            const std::string& where) -> const FieldDesc& {
        const FieldDesc* f = n.refl.find(r.channel);
        if (!f || f->kind != kind) {
            auto names = fieldNames(n, kind);
            std::string what = f ? fmt::format("'{}' is an {} of {}, not an {}", r.channel, fieldKindName(f->kind),
                                               n.desc.type, fieldKindName(kind))
                                 : fmt::format("unknown channel '{}' on pass '{}' ({})", r.channel, n.desc.name,
                                               n.desc.type);
            fail(where, what, fmt::format("an {} of {}: {}", fieldKindName(kind), n.desc.type, join(names)),
                 didYouMean(r.channel, names, ""));
        }
        return *f;
    };

    // 2. Explicit edges.
    std::vector<Wire> wires;
    std::map<std::string, size_t> wiredInputs;  // "Pass.input" -> wire index
    for (size_t i = 0; i < m.desc.edges.size(); ++i) {
        const EdgeDesc& e = m.desc.edges[i];
        const std::string where = fmt::format("/edges/{}", i);
        PassNode* src = resolvePass(e.src, where + "/0");
        PassNode* dst = resolvePass(e.dst, where + "/1");
        const FieldDesc& sf = resolveField(*src, e.src, FieldKind::Output, where + "/0");
        const FieldDesc& df = resolveField(*dst, e.dst, FieldKind::Input, where + "/1");
        if (sf.format != df.format)
            fail(where, fmt::format("wrong format on edge {} -> {}: the output is {} but the input is {}", e.src.str(),
                                    e.dst.str(), formatName(sf.format), formatName(df.format)),
                 fmt::format("an output of format {}", formatName(df.format)),
                 "connect a channel of the input's format, or put a conversion pass between them");
        std::string key = fieldKey(e.dst.pass, e.dst.channel);
        if (wiredInputs.count(key))
            fail(where, "input '" + key + "' is connected by more than one edge", "one edge per input",
                 "remove one of the edges");
        wiredInputs[key] = wires.size();
        wires.push_back(Wire{e.src, e.dst, false});
    }

    // 2b. Optional inputs a pass asks to leave unconnected: wiring by name skips them.
    std::set<std::string> unconnected;
    for (size_t i = 0; i < m.desc.passes.size(); ++i) {
        const PassDesc& pd = m.desc.passes[i];
        PassNode* n = m.node(pd.name);
        for (size_t k = 0; k < pd.unconnected.size(); ++k) {
            const std::string where = fmt::format("/passes/{}/unconnected/{}", i, k);
            const std::string key = fieldKey(pd.name, pd.unconnected[k]);
            const FieldDesc& f = resolveField(*n, ChannelRef{pd.name, pd.unconnected[k], false}, FieldKind::Input,
                                              where);
            if (!f.optional)
                fail(where, "input '" + key + "' is required and cannot be left unconnected",
                     "an optional input of " + pd.type, "remove it from \"unconnected\"");
            if (wiredInputs.count(key))
                fail(where, "input '" + key + "' is listed as unconnected but an edge connects it",
                     "the edge or the entry, not both", "remove one of them");
            unconnected.insert(key);
        }
    }

    // 3. Wiring by name for inputs without an edge. Problems are reported
    //    only for passes that end up live.
    std::map<std::string, std::string> wiringProblems;  // pass -> message (first one)
    std::map<std::string, std::pair<std::string, std::string>> wiringDetail;
    for (auto& n : m.nodes) {
        for (const auto& f : n->refl.fields()) {
            const std::string key = fieldKey(n->desc.name, f.name);
            if (f.kind != FieldKind::Input || wiredInputs.count(key) || unconnected.count(key)) continue;
            std::vector<std::string> producers;
            for (auto& other : m.nodes) {
                if (other.get() == n.get()) continue;
                const FieldDesc* o = other->refl.find(f.name);
                if (o && o->kind == FieldKind::Output) producers.push_back(fieldKey(other->desc.name, f.name));
            }
            const std::string where = fieldKey(n->desc.name, f.name);
            if (producers.size() == 1) {
                ChannelRef src = parseChannelRef(producers[0], where);
                const FieldDesc* sf = m.node(src.pass)->refl.find(src.channel);
                if (sf->format != f.format) {
                    if (!wiringProblems.count(n->desc.name)) {
                        wiringProblems[n->desc.name] = where;
                        wiringDetail[n->desc.name] = {
                            fmt::format("wrong format on the by-name connection {} -> {}: {} vs {}", producers[0],
                                        where, formatName(sf->format), formatName(f.format)),
                            "an explicit edge from an output of format " + std::string(formatName(f.format))};
                    }
                    continue;
                }
                wiredInputs[where] = wires.size();
                wires.push_back(Wire{src, ChannelRef{n->desc.name, f.name, false}, true});
            } else if (producers.empty()) {
                if (!f.optional && !wiringProblems.count(n->desc.name)) {
                    wiringProblems[n->desc.name] = where;
                    wiringDetail[n->desc.name] = {
                        "input '" + where + "' is not connected: no pass outputs a channel named '" + f.name + "'",
                        "an edge [\"Pass.output\", \"" + where + "\"] or a pass with an output '" + f.name + "'"};
                }
            } else if (!wiringProblems.count(n->desc.name)) {
                wiringProblems[n->desc.name] = where;
                wiringDetail[n->desc.name] = {
                    "input '" + where + "' is ambiguous: several passes output '" + f.name + "': " + join(producers),
                    "exactly one producer, or an explicit edge such as [\"" + producers[0] + "\", \"" + where +
                        "\"]"};
            }
        }
    }

    // 4. Marked outputs and observed fields.
    if (m.desc.outputs.empty())
        fail("/outputs", "the graph marks no outputs, so nothing would run", "at least one \"Pass.output\"",
             "add the channel you want to see to \"outputs\"");
    std::set<std::string> marked;
    for (size_t i = 0; i < m.desc.outputs.size(); ++i) {
        const ChannelRef& r = m.desc.outputs[i];
        const std::string where = fmt::format("/outputs/{}", i);
        PassNode* n = resolvePass(r, where);
        resolveField(*n, r, FieldKind::Output, where);
        marked.insert(fieldKey(r.pass, r.channel));
    }
    std::set<std::string> observed;  // "Pass.field" of any kind
    for (const auto& pattern : options.observe) {
        bool any = false;
        for (auto& n : m.nodes)
            for (const auto& f : n->refl.fields())
                if (globMatch(pattern, fieldKey(n->desc.name, f.name))) {
                    observed.insert(fieldKey(n->desc.name, f.name));
                    any = true;
                }
        if (!any) plan.warnings.push_back("'" + pattern + "' matches no field");
    }

    // 5. Culling: a pass is live when it reaches a marked or observed field.
    std::deque<PassNode*> work;
    auto markLive = [&](PassNode* n) {
        if (!n->live) {
            n->live = true;
            work.push_back(n);
        }
    };
    for (auto& n : m.nodes) n->live = false;
    for (const auto& r : m.desc.outputs) markLive(m.node(r.pass));
    for (const auto& key : observed) markLive(m.node(key.substr(0, key.find('.'))));
    while (!work.empty()) {
        PassNode* n = work.front();
        work.pop_front();
        for (const auto& w : wires)
            if (w.dst.pass == n->desc.name) markLive(m.node(w.src.pass));
    }
    for (auto& n : m.nodes) {
        if (!n->live) {
            plan.culled.push_back({n->desc.name, "does not contribute to a marked output"});
            if (wiringProblems.count(n->desc.name))
                plan.warnings.push_back(n->desc.name + " (culled): " + wiringDetail[n->desc.name].first);
        } else if (wiringProblems.count(n->desc.name)) {
            const auto& [what, expected] = wiringDetail[n->desc.name];
            fail(wiringProblems[n->desc.name], what, expected,
                 what.find("ambiguous") != std::string::npos ? "add an explicit edge naming the producer you want"
                                                             : "connect it with an edge or mark it optional");
        }
    }
    std::erase_if(wires, [&](const Wire& w) { return !m.node(w.dst.pass)->live; });

    // 6. Order: topological over same-frame wires, ties by description order.
    std::vector<PassNode*> live;
    for (auto& n : m.nodes)
        if (n->live) live.push_back(n.get());
    std::map<PassNode*, int> indegree;
    std::map<PassNode*, std::vector<PassNode*>> successors;
    for (auto* n : live) indegree[n] = 0;
    std::set<std::pair<PassNode*, PassNode*>> dependencies;
    for (const auto& w : wires) {
        if (w.src.prev) continue;
        PassNode* a = m.node(w.src.pass);
        PassNode* b = m.node(w.dst.pass);
        if (dependencies.insert({a, b}).second) {
            successors[a].push_back(b);
            ++indegree[b];
        }
    }
    std::vector<PassNode*> order;
    std::vector<bool> done(live.size(), false);
    while (order.size() < live.size()) {
        PassNode* next = nullptr;
        for (size_t i = 0; i < live.size(); ++i)
            if (!done[i] && indegree[live[i]] == 0) {
                next = live[i];
                done[i] = true;
                break;
            }
        if (!next) {
            // Every remaining pass waits on another remaining pass: walk
            // predecessors until one repeats, which closes a cycle.
            auto remaining = [&](PassNode* p) {
                for (size_t i = 0; i < live.size(); ++i)
                    if (live[i] == p) return !done[i];
                return false;
            };
            PassNode* cur = nullptr;
            for (size_t i = 0; i < live.size() && !cur; ++i)
                if (!done[i]) cur = live[i];
            std::vector<PassNode*> path;
            while (std::find(path.begin(), path.end(), cur) == path.end()) {
                path.push_back(cur);
                for (const auto& w : wires)
                    if (!w.src.prev && w.dst.pass == cur->desc.name && remaining(m.node(w.src.pass))) {
                        cur = m.node(w.src.pass);
                        break;
                    }
            }
            path.erase(path.begin(), std::find(path.begin(), path.end(), cur));
            std::reverse(path.begin(), path.end());
            std::vector<std::string> names;
            for (auto* p : path) names.push_back(p->desc.name);
            names.push_back(names.front());
            fail("/edges", "the graph has a cycle: " + join(names, " -> "), "an acyclic graph",
                 "to use last frame's value, make one edge's source \"Pass.channel@prev\"");
        }
        order.push_back(next);
        for (auto* s : successors[next]) --indegree[s];
    }
    const int N = int(order.size());
    for (int i = 0; i < N; ++i) order[i]->position = i;

    // 7. Which outputs are needed, and which feed history.
    std::set<std::string> consumed, prevConsumed;
    for (const auto& w : wires) (w.src.prev ? prevConsumed : consumed).insert(fieldKey(w.src.pass, w.src.channel));
    for (const auto& k : marked) consumed.insert(k);
    for (const auto& k : observed) consumed.insert(k);

    // 7b. What feeds each input, and each live pass's second reflection (CompileInfo::wired): it may leave out
    //     internal and history fields these connections do not use; its inputs and outputs must stay the same.
    std::map<std::string, const Wire*> wireInto;
    for (const auto& w : wires) wireInto[fieldKey(w.dst.pass, w.dst.channel)] = &w;
    auto wiredInfo = [&](const PassNode& n) {
        CompileInfo info;
        info.frameWidth = options.width;
        info.frameHeight = options.height;
        info.wired = true;
        for (const auto& f : n.refl.fields()) {
            const std::string key = fieldKey(n.desc.name, f.name);
            if (f.kind == FieldKind::Input && wireInto.count(key)) info.connectedInputs.push_back(f.name);
            if (f.kind == FieldKind::Output && (consumed.count(key) || prevConsumed.count(key) || !f.optional))
                info.consumedOutputs.push_back(f.name);
            if (observed.count(key)) info.observedFields.push_back(f.name);
        }
        return info;
    };
    for (PassNode* n : order) {
        Reflection wired;
        n->pass->reflect(wired, wiredInfo(*n));
        checkUniqueFields(wired, n->desc);
        if (portsOf(wired) != portsOf(n->refl))
            throw Error(Error::Info{
                ErrorKind::Runtime, {}, n->desc.name,
                "pass type '" + n->desc.type + "' declares other inputs or outputs once its connections are known",
                "the same inputs and outputs in both reflections (only internal and history fields may depend on "
                "the connections)",
                "fix the pass's reflect()"});
        for (const auto& f : n->refl.fields()) {
            const std::string key = fieldKey(n->desc.name, f.name);
            if (observed.count(key) && !wired.find(f.name)) {
                plan.warnings.push_back("'" + key + "' is not computed: " + n->desc.name +
                                        " does not use it with these connections");
                observed.erase(key);
            }
        }
        n->refl = std::move(wired);
    }

    // 8. Resources.
    struct Transient {
        ResourceInfo info;
        std::string key;
    };
    std::vector<Transient> transients;
    std::set<std::string> historyKeys;
    std::map<std::string, std::pair<std::string, FieldDesc>> historyDecl;  // key -> (pass type, decl)
    for (PassNode* n : order) {
        const int p = n->position;
        for (const auto& f : n->refl.fields()) {
            const std::string key = fieldKey(n->desc.name, f.name);
            uint32_t w, h;
            f.resolveSize(options.width, options.height, w, h);
            if (f.kind == FieldKind::Input) continue;
            if (f.kind == FieldKind::Output && f.optional && !consumed.count(key) && !prevConsumed.count(key)) {
                plan.skippedOutputs.push_back(key);
                continue;
            }
            if (f.kind == FieldKind::History || (f.kind == FieldKind::Output && prevConsumed.count(key))) {
                historyKeys.insert(key);
                historyDecl[key] = {n->desc.type, f};
                ResourceInfo r{key, ResourceKind::History, f.format, w, h, textureByteSize(w, h, f.format), 0, N, 0};
                plan.historyBytes += 2 * r.bytes;
                plan.resources.push_back(r);
                continue;
            }
            int last = p;
            if (f.kind == FieldKind::Output) {
                for (const auto& wi : wires)
                    if (!wi.src.prev && fieldKey(wi.src.pass, wi.src.channel) == key)
                        last = std::max(last, m.node(wi.dst.pass)->position);
                if (marked.count(key)) last = N;
            }
            // Observed fields stay readable through fieldTexture() after the frame, like marked outputs.
            if (observed.count(key)) last = N;
            transients.push_back({ResourceInfo{key, ResourceKind::Transient, f.format, w, h,
                                               textureByteSize(w, h, f.format), p, last, 0},
                                  key});
        }
    }

    // 9. Place transients in one arena: largest first, each at the lowest
    //    offset free of every placed resource whose lifetime overlaps.
    std::vector<size_t> idx(transients.size());
    for (size_t i = 0; i < idx.size(); ++i) idx[i] = i;
    std::stable_sort(idx.begin(), idx.end(),
                     [&](size_t a, size_t b) { return transients[a].info.bytes > transients[b].info.bytes; });
    std::vector<size_t> placed;
    size_t peak = 0;
    for (size_t i : idx) {
        ResourceInfo& r = transients[i].info;
        std::vector<std::pair<size_t, size_t>> busy;
        for (size_t j : placed) {
            const ResourceInfo& o = transients[j].info;
            if (o.firstUse <= r.lastUse && r.firstUse <= o.lastUse) busy.push_back({o.offset, o.offset + o.bytes});
        }
        std::sort(busy.begin(), busy.end());
        size_t offset = 0;
        for (const auto& [b, e] : busy) {
            if (offset + r.bytes <= b) break;
            offset = std::max(offset, alignUp(e, kRowAlignment));
        }
        r.offset = offset;
        peak = std::max(peak, offset + r.bytes);
        plan.transientSumBytes += r.bytes;
        placed.push_back(i);
    }
    plan.transientPeakBytes = peak;
    for (const auto& t : transients) plan.resources.push_back(t.info);

    // 10. Allocate: arena, then history (kept when its declaration is unchanged). The old plan's memory is
    //     released here, so until this compile succeeds there is no plan to execute.
    mCompiled = false;
    m.order.clear();
    m.transients.clear();
    m.fieldTextures.clear();
    if (!m.arena.reserve(peak))
        throw Error(Error::Info{ErrorKind::Runtime, file, {}, "out of memory for " + bytesText(peak) + " of frame data",
                                {}, "render at a smaller size"});
    for (const auto& t : transients) {
        auto tex = std::make_unique<Texture>(
            Texture::wrap(m.arena.data() + t.info.offset, t.info.width, t.info.height, t.info.format));
        m.fieldTextures[t.key] = tex.get();
        m.transients.push_back(std::move(tex));
    }
    for (auto it = m.history.begin(); it != m.history.end();) {
        if (!historyKeys.count(it->first)) {
            it = m.history.erase(it);
        } else {
            ++it;
        }
    }
    for (const auto& key : historyKeys) {
        const auto& [type, f] = historyDecl[key];
        uint32_t w, h;
        f.resolveSize(options.width, options.height, w, h);
        auto& entry = m.history[key];
        if (!entry || entry->passType != type || entry->format != f.format || entry->width != w || entry->height != h) {
            entry = std::make_unique<HistoryEntry>();
            entry->key = key;
            entry->passType = type;
            entry->format = f.format;
            entry->width = w;
            entry->height = h;
            entry->cur = Texture(w, h, f.format);
            entry->prev = Texture(w, h, f.format);
        }
        m.fieldTextures[key] = &entry->cur;
    }

    // 11. Bind each live pass's context and compile it.
    for (auto& n : m.nodes) {
        n->ctx = PassContext();
        n->observeBefore.clear();
        n->observeAfter.clear();
        n->poisonAtStart.clear();
        n->validFlags.clear();
        if (!n->live) {
            n->position = -1;
            continue;
        }
        n->ctx.mPassName = n->desc.name;
        n->ctx.mStats = &n->stats;
        const CompileInfo info = wiredInfo(*n);
        for (const auto& f : n->refl.fields()) {
            const std::string key = fieldKey(n->desc.name, f.name);
            BoundField b{f.name, f.kind};
            if (f.kind == FieldKind::Input) {
                auto it = wireInto.find(key);
                if (it != wireInto.end()) {
                    const Wire& w = *it->second;
                    const std::string srcKey = fieldKey(w.src.pass, w.src.channel);
                    if (w.src.prev) {
                        HistoryEntry& e = *m.history.at(srcKey);
                        b.cur = &e.prev;
                        b.valid = &e.valid;
                        n->validFlags.push_back(&e.valid);
                    } else {
                        b.cur = m.fieldTextures.at(srcKey);
                    }
                }
            } else if (f.kind == FieldKind::History ||
                       (f.kind == FieldKind::Output && m.history.count(key))) {
                HistoryEntry& e = *m.history.at(key);
                b.cur = &e.cur;
                b.prev = &e.prev;
                b.valid = &e.valid;
                if (f.kind == FieldKind::History) n->validFlags.push_back(&e.valid);
            } else if (auto it = m.fieldTextures.find(key); it != m.fieldTextures.end()) {
                b.cur = it->second;
                n->poisonAtStart.push_back(it->second);
            }
            if (observed.count(key) && b.cur) {
                (f.kind == FieldKind::Input ? n->observeBefore : n->observeAfter).push_back(f.name);
            }
            n->ctx.mFields.push_back(b);
        }
        n->info = info;
        n->pass->compile(info);
    }

    plan.order.clear();
    for (auto* n : order) plan.order.push_back(n->desc.name);
    plan.wires = wires;
    plan.outputs = m.desc.outputs;
    m.order = std::move(order);
    mPlan = std::move(plan);
    mOptions = options;
    mCompiled = true;
    for (const auto& w : mPlan.warnings) spdlog::warn("{}", w);
}

void RenderGraph::execute(const FrameInfo& frame) {
    if (!mCompiled) compile(mOptions);
    Impl& m = *mImpl;
    // Last frame's "cur" becomes this frame's "prev" (a swap, no copy).
    for (auto& [_, e] : m.history) {
        if (e->pendingSwap) {
            std::swap(e->cur, e->prev);
            e->valid = true;
            e->pendingSwap = false;
        }
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
        if (mObserver)
            for (const auto& name : n->observeBefore) mObserver(frame, n->desc.name, name, *ctx.input(name));
        n->stats.clear();
        auto t0 = std::chrono::steady_clock::now();
        try {
            n->pass->execute(ctx);
        } catch (const Error&) {
            throw;
        } catch (const std::bad_alloc&) {
            throw;
        } catch (const std::exception& e) {
            throw Error(Error::Info{ErrorKind::Runtime, {}, n->desc.name, std::string("pass failed: ") + e.what(), {},
                                    {}});
        } catch (...) {
            // A plugin may throw anything; it must not abort the process.
            throw Error(Error::Info{ErrorKind::Runtime, {}, n->desc.name,
                                    "pass failed with an exception that is not a std::exception", {},
                                    "report it to the plugin's author"});
        }
        auto t1 = std::chrono::steady_clock::now();
        double ms = std::chrono::duration<double, std::milli>(t1 - t0).count();
        n->timing.lastMs = ms;
        n->timing.totalMs += ms;
        ++n->timing.runs;
        if (mObserver) {
            for (const auto& name : n->observeAfter)
                for (const auto& b : ctx.mFields)
                    if (b.name == name && b.kind != FieldKind::Input) mObserver(frame, n->desc.name, name, *b.cur);
        }
    }
    for (auto& [_, e] : m.history) e->pendingSwap = true;
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
    s << "\nCulled passes:";
    if (p.culled.empty()) s << " none";
    s << "\n";
    for (const auto& c : p.culled) s << "  " << c.name << ": " << c.reason << "\n";
    s << "\nWiring:\n";
    for (const auto& w : p.wires)
        s << "  " << w.src.str() << " -> " << w.dst.str() << (w.byName ? "   (by name)" : "") << "\n";
    s << "\nMarked outputs:\n";
    for (const auto& o : p.outputs) s << "  " << o.str() << "\n";
    if (!p.skippedOutputs.empty()) s << "\nOptional outputs not computed: " << join(p.skippedOutputs) << "\n";
    s << "\nAllocations:\n";
    for (const auto& r : p.resources) {
        s << fmt::format("  {:28} {:10} {:>5}x{:<5} {:>11}  ", r.name, formatName(r.format), r.width, r.height,
                         bytesText(r.bytes));
        if (r.kind == ResourceKind::History)
            s << "history pair (2 textures)\n";
        else
            s << fmt::format("transient, passes {}..{}, offset {}\n", r.firstUse + 1,
                             r.lastUse >= int(p.order.size()) ? std::string("end") : std::to_string(r.lastUse + 1),
                             bytesText(r.offset));
    }
    double saved = p.transientSumBytes ? 100.0 * (1.0 - double(p.transientPeakBytes) / p.transientSumBytes) : 0.0;
    s << fmt::format("\nMemory: transient arena {} (unshared {}, {:.0f}% saved); history {}; peak {}\n",
                     bytesText(p.transientPeakBytes), bytesText(p.transientSumBytes), saved, bytesText(p.historyBytes),
                     bytesText(p.transientPeakBytes + p.historyBytes));
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
