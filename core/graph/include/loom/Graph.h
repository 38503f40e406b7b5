#pragma once
// The graph file format (docs/GRAPHS.md): passes, edges and marked outputs.
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <string_view>
#include <vector>

namespace loom {

inline constexpr int kGraphFormatVersion = 1;

struct PassDesc {
    std::string name;
    std::string type;
    nlohmann::json params = nlohmann::json::object();
    /// Optional inputs left unconnected: wiring by name skips them (e.g. SVGF's direct/indirect when the
    /// combined colour is to be filtered although the path tracer could split it).
    std::vector<std::string> unconnected;
    /// Where the pass runs: "" (the graph's device), "auto", "cpu", "cuda" or "emulated" (docs/GRAPHS.md).
    std::string device;
    bool operator==(const PassDesc&) const = default;
};

/// "Pass.channel" or "Pass.channel@prev".
struct ChannelRef {
    std::string pass;
    std::string channel;
    bool prev = false;
    std::string str() const { return pass + "." + channel + (prev ? "@prev" : ""); }
    bool operator==(const ChannelRef&) const = default;
};

struct EdgeDesc {
    ChannelRef src;
    ChannelRef dst;
    bool operator==(const EdgeDesc&) const = default;
};

struct GraphDesc {
    std::string name;
    std::vector<PassDesc> passes;
    std::vector<EdgeDesc> edges;
    std::vector<ChannelRef> outputs;
    /// Where passes run unless they say otherwise: "" (auto), "auto", "cpu", "cuda" or "emulated".
    std::string device;
    std::filesystem::path file;  ///< where it was loaded from (for error messages)

    const PassDesc* findPass(const std::string& name) const;
    /// Structural equality (ignores `file`).
    bool sameAs(const GraphDesc& o) const {
        return name == o.name && passes == o.passes && edges == o.edges && outputs == o.outputs && device == o.device;
    }
};

/// The device names a graph accepts: auto, cpu, cuda, emulated.
inline const std::vector<std::string>& deviceChoices() {
    static const std::vector<std::string> choices = {"auto", "cpu", "cuda", "emulated"};
    return choices;
}

/// Parses "Pass.channel[@prev]". Throws loom::Error naming `where` and `file`.
ChannelRef parseChannelRef(const std::string& text, const std::string& where, const std::string& file = {});

/// Parses graph JSON text. Throws loom::Error: malformed JSON (with line and
/// column), wrong version, missing or mistyped keys (with JSON path),
/// duplicate pass names, malformed channel references.
GraphDesc parseGraph(const std::string& text, const std::string& file = "<graph>");
/// Reads and parses a graph file; a missing or unreadable file is an error.
GraphDesc loadGraph(const std::filesystem::path& path);
/// Serialises to the versioned JSON format; parseGraph(saveGraph(g)) == g.
nlohmann::json graphToJson(const GraphDesc& g);
/// Writes a graph file atomically.
void saveGraph(const GraphDesc& g, const std::filesystem::path& path);

}  // namespace loom
