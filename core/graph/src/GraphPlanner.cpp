#include "loom/GraphPlanner.h"

#include <fmt/format.h>

#include <algorithm>
#include <functional>
#include <map>
#include <optional>
#include <queue>
#include <set>
#include <tuple>
#include <unordered_map>

#include "loom/Error.h"
#include "loom/Texture.h"

namespace loom {

namespace {

/// A pass's reflection must name each field once, with a plain name ("Pass.field" references and dump file names
/// are made of it).
void checkFields(const Reflection& r, const PassDesc& pass) {
    std::set<std::string> seen;
    std::set<FieldRole> roles;
    for (const auto& f : r.fields()) {
        // A role names one field of a pass, of the kind and format the role defines (Reflection.h).
        if (f.role != FieldRole::None) {
            const bool fits =
                f.role == FieldRole::DisplayInput && (f.kind == FieldKind::Input && f.format == Format::RGBA32F);
            const char* problem = !roles.insert(f.role).second ? "a second field with the role"
                                  : !fits                      ? "a field that cannot play the role"
                                                               : nullptr;
            if (problem)
                throw Error(Error::Info{ErrorKind::Runtime,
                                        {},
                                        fieldKey(pass.name, f.name),
                                        "pass type '" + pass.type + "' declares " + problem + " '" +
                                            fieldRoleName(f.role) + "' (field '" + printable(f.name) + "')",
                                        "at most one field per role: displayInput on an RGBA32F input",
                                        "fix the pass's reflect()"});
        }
        if (f.inPlace && f.kind != FieldKind::History)
            throw Error(Error::Info{ErrorKind::Runtime,
                                    {},
                                    fieldKey(pass.name, f.name),
                                    "pass type '" + pass.type + "' declares " + fieldKindName(f.kind) + " field '" +
                                        printable(f.name) + "' in place",
                                    "inPlace on history fields only",
                                    "fix the pass's reflect()"});
        if (!isPlainName(f.name))
            throw Error(Error::Info{ErrorKind::Runtime,
                                    {},
                                    pass.name,
                                    "pass type '" + pass.type + "' declares a field named '" + printable(f.name) +
                                        "', which is not a plain name",
                                    "a letter or _, then letters, digits and _",
                                    "fix the pass's reflect()"});
        if (!seen.insert(f.name).second)
            throw Error(Error::Info{ErrorKind::Runtime,
                                    {},
                                    fieldKey(pass.name, f.name),
                                    "pass type '" + pass.type + "' declares field '" + f.name + "' twice",
                                    "unique field names",
                                    "fix the pass's reflect()"});
    }
}

/// The inputs and outputs of a reflection, in declaration order.
std::vector<FieldDesc> portsOf(const Reflection& r) {
    std::vector<FieldDesc> ports;
    for (const auto& f : r.fields())
        if (f.kind == FieldKind::Input || f.kind == FieldKind::Output) ports.push_back(f);
    return ports;
}

/// A wire between two passes, by description index.
struct IndexedWire {
    uint32_t src = 0, dst = 0;
    Wire wire;
};

/// How many passes or fields a reason names before it says how many more there are.
constexpr size_t kMaxNamed = 4;

/// The first wiring problem of a pass: reported if the pass is live, a warning if it is culled.
struct WiringProblem {
    std::string where, what, expected;
};

/// The planner's working state for one graph.
class Planner {
public:
    explicit Planner(const PlannerInput& in) : mIn(in), mDesc(*in.desc), mFile(in.desc->file.string()) {
        const size_t n = mDesc.passes.size();
        for (size_t i = 0; i < n; ++i) mIndex.emplace(mDesc.passes[i].name, uint32_t(i));
        mPlan.passes.resize(n);
        for (size_t i = 0; i < n; ++i) {
            checkFields(in.reflections[i], mDesc.passes[i]);
            mPlan.passes[i].reflection = in.reflections[i];
        }
        mConsumed.resize(n);
        mPrevConsumed.resize(n);
        mMarked.resize(n);
        mObserved.resize(n);
        mWireInto.resize(n);
        mProblems.resize(n);
    }

    GraphPlan run() {
        mPlan.summary.width = mIn.width;
        mPlan.summary.height = mIn.height;
        explicitEdges();
        leftUnconnected();
        wireByName();
        markOutputs();
        cull();
        order();
        reflectWired();
        explainNotRun();
        return std::move(mPlan);
    }

private:
    [[noreturn]] void fail(std::string where, std::string what, std::string expected = {}, std::string hint = {}) {
        throwBadInput(std::move(where), std::move(what), std::move(expected), std::move(hint), mFile);
    }
    const Reflection& refl(uint32_t pass) const { return mPlan.passes[pass].reflection; }

    /// "A, B, C" of the passes (distinct, in description order), at most kMaxNamed of them, then "and N more".
    std::string namedPasses(std::vector<uint32_t> passes) const {
        std::sort(passes.begin(), passes.end());
        passes.erase(std::unique(passes.begin(), passes.end()), passes.end());
        std::vector<std::string> names;
        for (size_t i = 0; i < passes.size() && i < kMaxNamed; ++i) names.push_back(mDesc.passes[passes[i]].name);
        std::string text = join(names);
        if (passes.size() > kMaxNamed) text += fmt::format(" and {} more", passes.size() - kMaxNamed);
        return text;
    }

    std::vector<std::string> passNames() const {
        std::vector<std::string> out;
        for (const auto& p : mDesc.passes) out.push_back(p.name);
        return out;
    }

    uint32_t resolvePass(const ChannelRef& r, const std::string& where) {
        auto it = mIndex.find(r.pass);
        if (it == mIndex.end())
            fail(where, "unknown pass '" + r.pass + "' in '" + r.str() + "'", "one of: " + join(passNames()),
                 didYouMean(r.pass, passNames(), ""));
        return it->second;
    }

    const FieldDesc& resolveField(uint32_t pass, const ChannelRef& r, FieldKind kind, const std::string& where) {
        const FieldDesc* f = refl(pass).find(r.channel);
        if (!f || f->kind != kind) {
            const PassDesc& pd = mDesc.passes[pass];
            auto names = refl(pass).names(kind);
            std::string what = f ? fmt::format("'{}' is an {} of {}, not an {}", r.channel, fieldKindName(f->kind),
                                               pd.type, fieldKindName(kind))
                                 : fmt::format("unknown channel '{}' on pass '{}' ({})", r.channel, pd.name, pd.type);
            fail(where, what, fmt::format("an {} of {}: {}", fieldKindName(kind), pd.type, join(names)),
                 didYouMean(r.channel, names, ""));
        }
        return *f;
    }

    void addWire(uint32_t src, uint32_t dst, Wire w) {
        mWireInto[dst][w.dst.channel] = mWires.size();
        mWires.push_back(IndexedWire{src, dst, std::move(w)});
    }

    // Explicit edges.
    void explicitEdges() {
        for (size_t i = 0; i < mDesc.edges.size(); ++i) {
            const EdgeDesc& e = mDesc.edges[i];
            const std::string where = fmt::format("/edges/{}", i);
            const uint32_t src = resolvePass(e.src, where + "/0");
            const uint32_t dst = resolvePass(e.dst, where + "/1");
            const FieldDesc& sf = resolveField(src, e.src, FieldKind::Output, where + "/0");
            const FieldDesc& df = resolveField(dst, e.dst, FieldKind::Input, where + "/1");
            if (sf.format != df.format)
                fail(where,
                     fmt::format("wrong format on edge {} -> {}: the output is {} but the input is {}", e.src.str(),
                                 e.dst.str(), formatName(sf.format), formatName(df.format)),
                     fmt::format("an output of format {}", formatName(df.format)),
                     "connect a channel of the input's format, or put a conversion pass between them");
            if (mWireInto[dst].count(e.dst.channel))
                fail(where, "input '" + fieldKey(e.dst.pass, e.dst.channel) + "' is connected by more than one edge",
                     "one edge per input", "remove one of the edges");
            addWire(src, dst, Wire{e.src, e.dst, false});
        }
    }

    // Optional inputs a pass asks to leave unconnected: wiring by name skips them.
    void leftUnconnected() {
        mUnconnected.resize(mDesc.passes.size());
        for (size_t i = 0; i < mDesc.passes.size(); ++i) {
            const PassDesc& pd = mDesc.passes[i];
            for (size_t k = 0; k < pd.unconnected.size(); ++k) {
                const std::string where = fmt::format("/passes/{}/unconnected/{}", i, k);
                const std::string key = fieldKey(pd.name, pd.unconnected[k]);
                const FieldDesc& f =
                    resolveField(uint32_t(i), ChannelRef{pd.name, pd.unconnected[k], false}, FieldKind::Input, where);
                if (!f.optional)
                    fail(where, "input '" + key + "' is required and cannot be left unconnected",
                         "an optional input of " + pd.type, "remove it from \"unconnected\"");
                if (mWireInto[i].count(pd.unconnected[k]))
                    fail(where, "input '" + key + "' is listed as unconnected but an edge connects it",
                         "the edge or the entry, not both", "remove one of them");
                mUnconnected[i].insert(pd.unconnected[k]);
            }
        }
    }

    // Wiring by name for inputs without an edge. Problems are reported only for passes that end up live.
    void wireByName() {
        std::unordered_map<std::string, std::vector<uint32_t>> producers;  // channel -> passes, description order
        for (uint32_t p = 0; p < mDesc.passes.size(); ++p)
            for (const auto& f : refl(p).fields())
                if (f.kind == FieldKind::Output) producers[f.name].push_back(p);
        static const std::vector<uint32_t> kNone;
        for (uint32_t n = 0; n < mDesc.passes.size(); ++n) {
            const std::string& name = mDesc.passes[n].name;
            for (const auto& f : refl(n).fields()) {
                if (f.kind != FieldKind::Input || mWireInto[n].count(f.name) || mUnconnected[n].count(f.name)) continue;
                auto it = producers.find(f.name);
                const std::vector<uint32_t>& all = it == producers.end() ? kNone : it->second;
                std::vector<uint32_t> others;
                for (uint32_t p : all)
                    if (p != n) others.push_back(p);
                const std::string where = fieldKey(name, f.name);
                std::optional<WiringProblem>& problem = mProblems[n];
                if (others.size() == 1) {
                    const uint32_t src = others[0];
                    const FieldDesc* sf = refl(src).find(f.name);
                    const std::string srcKey = fieldKey(mDesc.passes[src].name, f.name);
                    if (sf->format != f.format) {
                        if (!problem)
                            problem = WiringProblem{
                                where,
                                fmt::format("wrong format on the by-name connection {} -> {}: {} vs {}", srcKey, where,
                                            formatName(sf->format), formatName(f.format)),
                                "an explicit edge from an output of format " + std::string(formatName(f.format))};
                        continue;
                    }
                    addWire(
                        src, n,
                        Wire{ChannelRef{mDesc.passes[src].name, f.name, false}, ChannelRef{name, f.name, false}, true});
                } else if (others.empty()) {
                    if (!f.optional && !problem)
                        problem = WiringProblem{
                            where,
                            "input '" + where + "' is not connected: no pass outputs a channel named '" + f.name + "'",
                            "an edge [\"Pass.output\", \"" + where + "\"] or a pass with an output '" + f.name + "'"};
                } else if (!problem) {
                    std::vector<std::string> keys;
                    for (uint32_t p : others) keys.push_back(fieldKey(mDesc.passes[p].name, f.name));
                    problem = WiringProblem{
                        where,
                        "input '" + where + "' is ambiguous: several passes output '" + f.name + "': " + join(keys),
                        "exactly one producer, or an explicit edge such as [\"" + keys[0] + "\", \"" + where + "\"]"};
                }
            }
        }
    }

    // Marked outputs and observed fields.
    void markOutputs() {
        if (mDesc.outputs.empty())
            fail("/outputs", "the graph marks no outputs, so nothing would run", "at least one \"Pass.output\"",
                 "add the channel you want to see to \"outputs\"");
        for (size_t i = 0; i < mDesc.outputs.size(); ++i) {
            const ChannelRef& r = mDesc.outputs[i];
            const std::string where = fmt::format("/outputs/{}", i);
            const uint32_t p = resolvePass(r, where);
            resolveField(p, r, FieldKind::Output, where);
            mMarked[p].insert(r.channel);
        }
        for (const auto& pattern : mIn.observe) {
            bool any = false;
            for (uint32_t p = 0; p < mDesc.passes.size(); ++p)
                for (const auto& f : refl(p).fields())
                    if (globMatch(pattern, fieldKey(mDesc.passes[p].name, f.name))) {
                        mObserved[p].insert(f.name);
                        any = true;
                    }
            if (!any) mPlan.summary.warnings.push_back("'" + pattern + "' matches no field");
        }
    }

    // Culling: a pass is live when it reaches a marked or observed field.
    void cull() {
        const size_t n = mDesc.passes.size();
        std::vector<std::vector<uint32_t>> sources(n);
        for (const auto& w : mWires) sources[w.dst].push_back(w.src);
        std::vector<uint32_t> work;
        auto markLive = [&](uint32_t p) {
            if (!mPlan.passes[p].live) {
                mPlan.passes[p].live = true;
                work.push_back(p);
            }
        };
        for (const auto& r : mDesc.outputs) markLive(mIndex.at(r.pass));
        for (uint32_t p = 0; p < n; ++p)
            if (!mObserved[p].empty()) markLive(p);
        while (!work.empty()) {
            const uint32_t p = work.back();
            work.pop_back();
            for (uint32_t s : sources[p]) markLive(s);
        }
        // What culled passes would have read, by source and output: why their sources, and optional outputs of
        // live passes, are not needed.
        mCulledReads.resize(n);
        for (const auto& w : mWires)
            if (!mPlan.passes[w.dst].live) mCulledReads[w.src].emplace_back(w.wire.src.channel, w.dst);
        for (auto& reads : mCulledReads) std::sort(reads.begin(), reads.end());
        for (uint32_t p = 0; p < n; ++p) {
            const std::string& name = mDesc.passes[p].name;
            if (!mPlan.passes[p].live) {
                mPlan.summary.culled.push_back({name, culledReason(p)});
                if (mProblems[p]) mPlan.summary.warnings.push_back(name + " (culled): " + mProblems[p]->what);
            } else if (mProblems[p]) {
                const WiringProblem& w = *mProblems[p];
                fail(w.where, w.what, w.expected,
                     w.what.find("ambiguous") != std::string::npos ? "add an explicit edge naming the producer you want"
                                                                   : "connect it with an edge or mark it optional");
            }
        }
        std::erase_if(mWires, [&](const IndexedWire& w) { return !mPlan.passes[w.dst].live; });
        for (auto& into : mWireInto) into.clear();
        for (size_t i = 0; i < mWires.size(); ++i) mWireInto[mWires[i].dst][mWires[i].wire.dst.channel] = i;
    }

    /// Why a pass is culled: no marked or observed field depends on it, directly or through the passes that read it.
    std::string culledReason(uint32_t p) const {
        std::vector<uint32_t> readers;
        bool self = false;
        for (const auto& [field, dst] : mCulledReads[p]) {
            if (dst == p)
                self = true;
            else
                readers.push_back(dst);
        }
        if (!readers.empty()) return "only culled passes read its outputs: " + namedPasses(std::move(readers));
        if (refl(p).names(FieldKind::Output).empty()) return "it has no outputs, and none of its fields is observed";
        if (self) return "only itself reads its outputs (through @prev), and none is marked or observed";
        return "no pass reads its outputs, and none is marked or observed";
    }

    // Order: topological over same-frame wires, ties by description order (the lowest ready index runs first).
    void order() {
        const size_t n = mDesc.passes.size();
        std::vector<std::vector<uint32_t>> successors(n);
        std::vector<uint32_t> indegree(n, 0);
        std::set<std::pair<uint32_t, uint32_t>> dependencies;
        for (const auto& w : mWires) {
            if (w.wire.src.prev || !dependencies.insert({w.src, w.dst}).second) continue;
            successors[w.src].push_back(w.dst);
            ++indegree[w.dst];
        }
        std::priority_queue<uint32_t, std::vector<uint32_t>, std::greater<>> ready;
        size_t liveCount = 0;
        for (uint32_t p = 0; p < n; ++p) {
            if (!mPlan.passes[p].live) continue;
            ++liveCount;
            if (indegree[p] == 0) ready.push(p);
        }
        std::vector<uint32_t>& order = mPlan.order;
        while (!ready.empty()) {
            const uint32_t p = ready.top();
            ready.pop();
            mPlan.passes[p].position = int(order.size());
            order.push_back(p);
            for (uint32_t s : successors[p])
                if (--indegree[s] == 0) ready.push(s);
        }
        if (order.size() < liveCount) reportCycle();
        for (uint32_t p : order) {
            mPlan.summary.order.push_back(mDesc.passes[p].name);
            PassPlan& pp = mPlan.passes[p];
            if (p < mIn.devices.size()) pp.device = mIn.devices[p];
            mPlan.summary.placement.push_back(
                {mDesc.passes[p].name, pp.device, p < mIn.deviceNotes.size() ? mIn.deviceNotes[p] : std::string()});
        }
    }

    // Every remaining pass waits on another remaining pass: walk predecessors from the first one until one repeats,
    // which closes a cycle.
    [[noreturn]] void reportCycle() {
        const size_t n = mDesc.passes.size();
        auto remaining = [&](uint32_t p) { return mPlan.passes[p].live && mPlan.passes[p].position < 0; };
        std::vector<std::vector<uint32_t>> sources(n);  // same-frame sources, in wire order
        for (const auto& w : mWires)
            if (!w.wire.src.prev) sources[w.dst].push_back(w.src);
        uint32_t cur = 0;
        while (!remaining(cur)) ++cur;
        std::vector<int> seenAt(n, -1);
        std::vector<uint32_t> path;
        while (seenAt[cur] < 0) {
            seenAt[cur] = int(path.size());
            path.push_back(cur);
            for (uint32_t s : sources[cur])
                if (remaining(s)) {
                    cur = s;
                    break;
                }
        }
        path.erase(path.begin(), path.begin() + seenAt[cur]);
        std::reverse(path.begin(), path.end());
        std::vector<std::string> names;
        for (uint32_t p : path) names.push_back(mDesc.passes[p].name);
        names.push_back(names.front());
        fail("/edges", "the graph has a cycle: " + join(names, " -> "), "an acyclic graph",
             "to use last frame's value, make one edge's source \"Pass.channel@prev\"");
    }

    CompileInfo wiredInfo(uint32_t p, const Reflection& r) const {
        CompileInfo info;
        info.frameWidth = mIn.width;
        info.frameHeight = mIn.height;
        info.wired = true;
        for (const auto& f : r.fields()) {
            if (f.kind == FieldKind::Input && mWireInto[p].count(f.name)) info.connectedInputs.push_back(f.name);
            if (f.kind == FieldKind::Output &&
                (mConsumed[p].count(f.name) || mPrevConsumed[p].count(f.name) || !f.optional))
                info.consumedOutputs.push_back(f.name);
            if (f.kind == FieldKind::Output && (mRead[p].count(f.name) || mPrevConsumed[p].count(f.name)))
                info.readOutputs.push_back(f.name);
            if (mObserved[p].count(f.name)) info.observedFields.push_back(f.name);
        }
        return info;
    }

    // Which outputs are consumed, what feeds each input, and each live pass's second reflection: it may leave out
    // internal and history fields these connections do not use; its inputs and outputs must stay the same.
    void reflectWired() {
        mLeftOut.resize(mDesc.passes.size());
        mRead.resize(mDesc.passes.size());
        for (const auto& w : mWires) (w.wire.src.prev ? mPrevConsumed : mConsumed)[w.src].insert(w.wire.src.channel);
        for (size_t p = 0; p < mDesc.passes.size(); ++p) {
            mConsumed[p].insert(mMarked[p].begin(), mMarked[p].end());
            mRead[p] = mConsumed[p];  // before the observed fields join: what the pass must really produce
            mConsumed[p].insert(mObserved[p].begin(), mObserved[p].end());
        }
        for (uint32_t p : mPlan.order) {
            PassPlan& pp = mPlan.passes[p];
            const PassDesc& pd = mDesc.passes[p];
            if (mIn.reflectWired) {
                Reflection wired = mIn.reflectWired(p, wiredInfo(p, pp.reflection));
                checkFields(wired, pd);
                if (portsOf(wired) != portsOf(pp.reflection))
                    throw Error(Error::Info{
                        ErrorKind::Runtime,
                        {},
                        pd.name,
                        "pass type '" + pd.type + "' declares other inputs or outputs once its connections are known",
                        "the same inputs and outputs in both reflections (only internal and "
                        "history fields may depend on the connections)",
                        "fix the pass's reflect()"});
                for (const auto& f : pp.reflection.fields()) {
                    if (wired.find(f.name)) continue;
                    mLeftOut[p].push_back(f);
                    if (mObserved[p].count(f.name)) {
                        mPlan.summary.warnings.push_back("'" + fieldKey(pd.name, f.name) + "' is not computed: " +
                                                         pd.name + " does not use it with these connections");
                        mObserved[p].erase(f.name);
                    }
                }
                pp.reflection = std::move(wired);
            }
            pp.info = wiredInfo(p, pp.reflection);
            for (const auto& f : pp.reflection.fields())
                if (mObserved[p].count(f.name)) pp.observed.push_back(f.name);
            for (const auto& f : pp.reflection.fields()) {
                if (f.kind != FieldKind::Input) continue;
                auto it = mWireInto[p].find(f.name);
                if (it == mWireInto[p].end()) continue;
                const IndexedWire& w = mWires[it->second];
                pp.inputs.push_back(PlannedInput{f.name, w.src, w.wire.src.channel, w.wire.src.prev});
            }
        }
        for (const auto& w : mWires) mPlan.summary.wires.push_back(w.wire);
        mPlan.summary.outputs = mDesc.outputs;
        for (uint32_t p : mPlan.order) {
            PassPlan& pp = mPlan.passes[p];
            pp.consumed = mConsumed[p];
            pp.history = mPrevConsumed[p];
            pp.kept = mMarked[p];
            pp.kept.insert(pp.observed.begin(), pp.observed.end());
        }
    }

    /// Why an optional output of a live pass is not computed: culled passes read it, or nothing does (inputs of its
    /// name are listed as unconnected or read another output).
    std::string unreadOutputReason(uint32_t p, const std::string& field) {
        const auto& reads = mCulledReads[p];
        auto first = std::lower_bound(reads.begin(), reads.end(), std::make_pair(field, uint32_t(0)));
        std::vector<uint32_t> readers;
        for (auto it = first; it != reads.end() && it->first == field; ++it) readers.push_back(it->second);
        if (!readers.empty()) return "optional, and only culled passes read it: " + namedPasses(std::move(readers));
        if (!mInputsIndexed) {
            mInputsIndexed = true;
            for (uint32_t q = 0; q < mDesc.passes.size(); ++q)
                if (mPlan.passes[q].live)
                    for (const auto& f : refl(q).fields())
                        if (f.kind == FieldKind::Input) mInputsNamed[f.name].push_back(q);
        }
        std::vector<std::string> notes;
        bool more = false;
        if (auto it = mInputsNamed.find(field); it != mInputsNamed.end()) {
            for (uint32_t q : it->second) {
                if (q == p) continue;
                if (notes.size() == kMaxNamed) {
                    more = true;
                    break;
                }
                const std::string key = fieldKey(mDesc.passes[q].name, field);
                if (mUnconnected[q].count(field))
                    notes.push_back(key + " is listed as unconnected");
                else if (auto w = mWireInto[q].find(field); w != mWireInto[q].end())
                    notes.push_back(key + " reads " + mWires[w->second].wire.src.str());
            }
        }
        if (notes.empty()) return "optional, not marked or observed, and no pass reads it";
        return "optional, not marked or observed, and no pass reads it (" + join(notes, "; ") + (more ? "; ..." : "") +
               ")";
    }

    /// Each culled pass, and each optional output not computed, optional input not connected and field left out of
    /// a live pass, with why (CompiledPlan::notRun).
    void explainNotRun() {
        std::vector<NotRun>& out = mPlan.summary.notRun;
        size_t culled = 0;
        for (uint32_t p = 0; p < mDesc.passes.size(); ++p) {
            const std::string& name = mDesc.passes[p].name;
            const PassPlan& pp = mPlan.passes[p];
            if (!pp.live) {
                out.push_back({name, {}, NotRunKind::Culled, mPlan.summary.culled[culled++].reason});
                continue;
            }
            for (const auto& f : pp.reflection.fields()) {
                if (f.kind == FieldKind::Input && !mWireInto[p].count(f.name))
                    out.push_back({name, f.name, NotRunKind::NotConnected,
                                   mUnconnected[p].count(f.name)
                                       ? "optional, and listed in the pass's \"unconnected\""
                                       : "optional, and no pass outputs a channel named '" + f.name + "'"});
                if (f.kind == FieldKind::Output && f.optional && !pp.consumed.count(f.name) &&
                    !pp.history.count(f.name))
                    out.push_back({name, f.name, NotRunKind::NotComputed, unreadOutputReason(p, f.name)});
            }
            for (const auto& f : mLeftOut[p])
                out.push_back(
                    {name, f.name, NotRunKind::NotAllocated,
                     fmt::format("{} field the pass does not use with these connections", fieldKindName(f.kind))});
        }
    }

    const PlannerInput& mIn;
    const GraphDesc& mDesc;
    std::string mFile;
    GraphPlan mPlan;
    std::unordered_map<std::string, uint32_t> mIndex;  // pass name -> description index
    std::vector<IndexedWire> mWires;
    std::vector<std::map<std::string, size_t>> mWireInto;  // per pass: input -> wire
    std::vector<std::set<std::string>> mUnconnected, mConsumed, mPrevConsumed, mRead, mMarked, mObserved;
    std::vector<std::optional<WiringProblem>> mProblems;
    // Per pass: (output, culled pass that reads it), sorted.
    std::vector<std::vector<std::pair<std::string, uint32_t>>> mCulledReads;
    std::vector<std::vector<FieldDesc>> mLeftOut;  // per live pass: fields its second reflection leaves out
    std::unordered_map<std::string, std::vector<uint32_t>> mInputsNamed;  // input name -> live passes; built on demand
    bool mInputsIndexed = false;
};

/// Placed transients, found by lifetime: bucketed by the first position of their lifetime, under a max-tree of
/// the last positions, so the transients alive during [first, last] are found without visiting the others.
class LifetimeIndex {
public:
    explicit LifetimeIndex(int positions) {
        while (mSize < size_t(std::max(positions, 1))) mSize *= 2;
        mMaxLast.assign(2 * mSize, -1);
        mByFirst.resize(mSize);
    }
    void add(int first, int last, size_t id) {
        mByFirst[size_t(first)].push_back({last, id});
        for (size_t node = size_t(first) + mSize; node >= 1; node /= 2) mMaxLast[node] = std::max(mMaxLast[node], last);
    }
    /// Calls fn(id) for each added transient whose lifetime overlaps [first, last].
    template <class F>
    void overlapping(int first, int last, F&& fn) const {
        visit(1, 0, int(mSize) - 1, first, last, fn);
    }

private:
    template <class F>
    void visit(size_t node, int lo, int hi, int first, int last, F& fn) const {
        if (lo > last || mMaxLast[node] < first) return;  // all start after it, or all end before it
        if (lo == hi) {
            for (const auto& [end, id] : mByFirst[size_t(lo)])
                if (end >= first) fn(id);
            return;
        }
        const int mid = lo + (hi - lo) / 2;
        visit(2 * node, lo, mid, first, last, fn);
        visit(2 * node + 1, mid + 1, hi, first, last, fn);
    }

    size_t mSize = 1;
    std::vector<int> mMaxLast;
    std::vector<std::vector<std::pair<int, size_t>>> mByFirst;
};

/// Places the transients `ids` (all of one device's arena) largest first, each at the lowest offset free of every
/// placed transient whose lifetime overlaps its own; returns the arena's size.
size_t placeTransients(std::vector<ResourceInfo>& transients, std::vector<size_t> ids, int positions) {
    std::stable_sort(ids.begin(), ids.end(),
                     [&](size_t a, size_t b) { return transients[a].bytes > transients[b].bytes; });
    LifetimeIndex placed(positions);
    size_t peak = 0;
    std::vector<std::pair<size_t, size_t>> busy;
    for (size_t i : ids) {
        ResourceInfo& r = transients[i];
        busy.clear();
        placed.overlapping(r.firstUse, r.lastUse, [&](size_t j) {
            busy.push_back({transients[j].offset, transients[j].offset + transients[j].bytes});
        });
        std::sort(busy.begin(), busy.end());
        size_t offset = 0;
        for (const auto& [b, e] : busy) {
            if (offset + r.bytes <= b) break;
            offset = std::max(offset, alignUp(e, kRowAlignment));
        }
        r.offset = offset;
        peak = std::max(peak, offset + r.bytes);
        placed.add(r.firstUse, r.lastUse, i);
    }
    return peak;
}

/// Copies where a field crosses devices: into each reader placed elsewhere than the field's writer (one copy per
/// field and device, a transient on the reader's device living from its first reader there to its last, made
/// before the first), and to the host for each marked output or observed field of a pass off the host.
void planTransfers(GraphPlan& plan, const GraphDesc& desc, std::vector<ResourceInfo>& transients) {
    CompiledPlan& s = plan.summary;
    std::map<std::tuple<uint32_t, std::string, bool, DeviceKind>, int> copies;  // (writer, field, prev, device)
    for (uint32_t p : plan.order) {
        PassPlan& pp = plan.passes[p];
        for (PlannedInput& in : pp.inputs) {
            const PassPlan& src = plan.passes[in.srcPass];
            if (src.device == pp.device) continue;
            const auto key = std::make_tuple(in.srcPass, in.srcField, in.prev, pp.device);
            auto [it, added] = copies.emplace(key, int(s.transfers.size()));
            if (added) {
                const FieldDesc* f = src.reflection.find(in.srcField);
                uint32_t w = s.width, h = s.height;
                if (f) f->resolveSize(s.width, s.height, w, h);
                const Format format = f ? f->format : Format::RGBA32F;
                TransferInfo t;
                t.field = fieldKey(desc.passes[in.srcPass].name, in.srcField) + (in.prev ? "@prev" : "");
                t.from = src.device;
                t.to = pp.device;
                t.bytes = textureByteSize(w, h, format);
                t.position = pp.position;
                t.reason = "for " + desc.passes[p].name;
                t.resource = t.field + " on " + deviceName(pp.device);
                s.transfers.push_back(t);
                transients.push_back(ResourceInfo{t.resource, p, in.field, ResourceKind::Transient, format, w, h,
                                                  t.bytes, pp.device, pp.position, pp.position, 0});
            } else {
                TransferInfo& t = s.transfers[size_t(it->second)];
                if (t.reason.find(" " + desc.passes[p].name) == std::string::npos) t.reason += ", " + desc.passes[p].name;
                for (auto& r : transients)
                    if (r.name == t.resource) r.lastUse = std::max(r.lastUse, pp.position);
            }
            in.transfer = it->second;
        }
    }
    for (uint32_t p : plan.order) {
        const PassPlan& pp = plan.passes[p];
        if (pp.device == DeviceKind::Cpu) continue;
        for (const auto& f : pp.reflection.fields()) {
            if (!pp.kept.count(f.name) && std::find(pp.observed.begin(), pp.observed.end(), f.name) == pp.observed.end())
                continue;
            uint32_t w, h;
            f.resolveSize(s.width, s.height, w, h);
            TransferInfo t;
            t.field = fieldKey(desc.passes[p].name, f.name);
            t.from = pp.device;
            t.to = DeviceKind::Cpu;
            t.bytes = textureByteSize(w, h, f.format);
            t.position = pp.position;
            t.after = true;
            const bool marked = std::any_of(s.outputs.begin(), s.outputs.end(), [&](const ChannelRef& o) {
                return o.pass == desc.passes[p].name && o.channel == f.name;
            });
            t.reason = marked ? "marked output" : "observed";
            s.transfers.push_back(t);
        }
    }
}

}  // namespace

GraphPlan planGraph(const PlannerInput& input) {
    return Planner(input).run();
}

void planResources(GraphPlan& plan, const GraphDesc& desc) {
    CompiledPlan& s = plan.summary;
    const int n = int(plan.order.size());
    // The last position that reads each output in the same frame.
    std::vector<std::map<std::string, int>> lastRead(plan.passes.size());
    for (uint32_t p : plan.order)
        for (const auto& in : plan.passes[p].inputs)
            if (!in.prev) {
                auto [it, added] = lastRead[in.srcPass].emplace(in.srcField, plan.passes[p].position);
                if (!added) it->second = std::max(it->second, plan.passes[p].position);
            }
    std::vector<ResourceInfo> transients;
    for (uint32_t p : plan.order) {
        const PassPlan& pp = plan.passes[p];
        const std::string& name = desc.passes[p].name;
        for (const auto& f : pp.reflection.fields()) {
            if (f.kind == FieldKind::Input) continue;
            const std::string key = fieldKey(name, f.name);
            uint32_t w, h;
            f.resolveSize(s.width, s.height, w, h);
            ResourceInfo r{key,         p,           f.name, ResourceKind::Transient,
                           f.format,    w,           h,      textureByteSize(w, h, f.format),
                           pp.device,   pp.position, pp.position, 0};
            const bool history = pp.history.count(f.name) > 0;
            if (f.kind == FieldKind::Output && f.optional && !pp.consumed.count(f.name) && !history) {
                s.skippedOutputs.push_back(key);
                continue;
            }
            if (f.kind == FieldKind::History || (f.kind == FieldKind::Output && history)) {
                r.kind = ResourceKind::History;
                r.firstUse = 0;
                r.lastUse = n;
                r.inPlace = f.kind == FieldKind::History && f.inPlace;
                s.historyBytes += (r.inPlace ? 1 : 2) * r.bytes;
                s.deviceHistoryBytes[size_t(r.device)] += (r.inPlace ? 1 : 2) * r.bytes;
                s.resources.push_back(std::move(r));
                continue;
            }
            if (f.kind == FieldKind::Output)
                if (auto it = lastRead[p].find(f.name); it != lastRead[p].end())
                    r.lastUse = std::max(r.lastUse, it->second);
            // Marked outputs and observed fields stay readable through fieldTexture() after the frame.
            if (pp.kept.count(f.name)) r.lastUse = n;
            transients.push_back(std::move(r));
        }
    }
    planTransfers(plan, desc, transients);

    // Each device has its own arena: transients are placed per device.
    for (DeviceKind device : {DeviceKind::Cpu, DeviceKind::Cuda, DeviceKind::Emulated}) {
        std::vector<size_t> bySize;
        for (size_t i = 0; i < transients.size(); ++i)
            if (transients[i].device == device) bySize.push_back(i);
        if (bySize.empty()) continue;
        s.devicePeakBytes[size_t(device)] = placeTransients(transients, bySize, n);
        s.transientPeakBytes += s.devicePeakBytes[size_t(device)];
    }
    for (const auto& t : transients) s.transientSumBytes += t.bytes;
    for (auto& t : transients) s.resources.push_back(std::move(t));
}

}  // namespace loom
