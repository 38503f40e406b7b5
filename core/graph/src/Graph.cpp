#include "loom/Graph.h"

#include <fmt/format.h>

#include <algorithm>
#include <cctype>
#include <fstream>
#include <set>
#include <sstream>

#include "loom/Error.h"
#include "loom/Files.h"
#include "loom/InputFile.h"

namespace loom {

using json = nlohmann::json;

const PassDesc* GraphDesc::findPass(const std::string& n) const {
    for (const auto& p : passes)
        if (p.name == n) return &p;
    return nullptr;
}


ChannelRef parseChannelRef(const std::string& text, const std::string& where, const std::string& file) {
    ChannelRef r;
    std::string s = text;
    const std::string suffix = "@prev";
    if (auto at = s.find('@'); at != std::string::npos) {
        if (s.substr(at) != suffix)
            throwBadInput(where, "'" + text + "' has an unknown modifier '" + s.substr(at) + "'",
                          "\"Pass.channel\" or \"Pass.channel@prev\"", "the only modifier is @prev", file);
        r.prev = true;
        s = s.substr(0, at);
    }
    auto dot = s.find('.');
    if (dot == std::string::npos || dot == 0 || dot + 1 == s.size() || s.find('.', dot + 1) != std::string::npos)
        throwBadInput(where, "'" + text + "' is not a channel reference", "\"Pass.channel\" or \"Pass.channel@prev\"",
                      "write the pass name, a dot and the channel name", file);
    r.pass = s.substr(0, dot);
    r.channel = s.substr(dot + 1);
    return r;
}

namespace {

/// A "device" value: auto, cpu, cuda or emulated.
std::string readDevice(const json& v, const std::string& where, const std::string& file) {
    const std::string text = v.is_string() ? v.get<std::string>() : v.dump();
    const auto& choices = deviceChoices();
    if (!v.is_string() || std::find(choices.begin(), choices.end(), text) == choices.end())
        throwBadInput(where, "unknown device " + (v.is_string() ? "'" + text + "'" : text), "one of: " + join(choices),
                      v.is_string() ? didYouMean(text, choices, "") : std::string(), file);
    return text;
}

void checkKeys(const json& obj, const std::vector<std::string>& allowed, const std::string& where,
               const std::string& file) {
    for (auto it = obj.begin(); it != obj.end(); ++it) {
        if (std::find(allowed.begin(), allowed.end(), it.key()) == allowed.end())
            throwBadInput(where + "/" + it.key(), "unknown key '" + it.key() + "'", "one of: " + join(allowed),
                          didYouMean(it.key(), allowed, ""), file);
    }
}

const json& require(const json& obj, const std::string& key, json::value_t type, const char* typeName,
                    const std::string& where, const std::string& file) {
    if (!obj.contains(key))
        throwBadInput(where, "missing key '" + key + "'", std::string("\"") + key + "\": " + typeName, {}, file);
    const json& v = obj[key];
    bool ok = v.type() == type || (type == json::value_t::number_integer && v.is_number_integer());
    if (!ok)
        throwBadInput(where + "/" + key, "'" + key + "' has the wrong type: " + std::string(v.type_name()), typeName,
                      {}, file);
    return v;
}

}  // namespace

constexpr size_t kMaxPassNameLength = 64;

GraphDesc parseGraph(const std::string& text, const std::string& file) {
    checkJsonText(text, file);
    json root;
    try {
        root = json::parse(text);
    } catch (const json::parse_error& e) {
        size_t line, col;
        lineColumn(text, e.byte > 0 ? e.byte - 1 : 0, line, col);
        std::string msg = e.what();
        if (auto p = msg.find("syntax error"); p != std::string::npos) msg = msg.substr(p);
        throwBadInput(fmt::format("line {}, column {}", line, col), "malformed JSON: " + msg, "valid JSON",
                      "check for a missing comma, quote or bracket just before this point", file);
    }
    if (!root.is_object()) throwBadInput("/", "a graph must be a JSON object", "{\"loom_graph\": 1, ...}", {}, file);
    checkKeys(root, {"loom_graph", "name", "device", "passes", "edges", "outputs"}, "", file);
    const json& version = require(root, "loom_graph", json::value_t::number_integer, "an integer", "", file);
    // Compared as a 64-bit value: an int conversion would take 4294967297 for 1.
    if (!version.is_number_integer() || version.get<int64_t>() != int64_t(kGraphFormatVersion))
        throwBadInput("/loom_graph", fmt::format("unsupported graph format version {}", version.dump()),
                      fmt::format("{}", kGraphFormatVersion), "this Loom reads version 1 graphs", file);

    GraphDesc g;
    g.file = file;
    if (root.contains("name")) {
        if (!root["name"].is_string()) throwBadInput("/name", "'name' must be a string", "a string", {}, file);
        g.name = root["name"].get<std::string>();
    }
    if (root.contains("device")) g.device = readDevice(root["device"], "/device", file);
    const json& passes = require(root, "passes", json::value_t::array, "an array of passes", "", file);
    std::set<std::string> names;
    for (size_t i = 0; i < passes.size(); ++i) {
        const std::string where = fmt::format("/passes/{}", i);
        const json& p = passes[i];
        if (!p.is_object())
            throwBadInput(where, "a pass must be an object", "{\"name\": ..., \"type\": ...}", {}, file);
        checkKeys(p, {"name", "type", "params", "unconnected", "device"}, where, file);
        PassDesc d;
        d.name = require(p, "name", json::value_t::string, "a string", where, file).get<std::string>();
        d.type = require(p, "type", json::value_t::string, "a string", where, file).get<std::string>();
        // Names become parts of file names (Pass.field.0001.exr) and of "Pass.field" references.
        const bool allowed = !d.name.empty() && d.name.size() <= kMaxPassNameLength && printable(d.name) == d.name &&
                             std::none_of(d.name.begin(), d.name.end(), [](char c) {
                                 return static_cast<unsigned char>(c) < 0x20 || c == 0x7F ||
                                        std::string_view(".@ /\\:*?\"<>|").find(c) != std::string_view::npos;
                             });
        if (!allowed)
            throwBadInput(where + "/name",
                          "pass name '" + printable(d.name.substr(0, kMaxPassNameLength)) +
                              (d.name.size() > kMaxPassNameLength ? "...'" : "'") + " is not allowed",
                          fmt::format("1 to {} bytes of UTF-8 without spaces, control or invisible formatting "
                                      "characters or any of . @ / \\ : * ? \" < > |",
                                      kMaxPassNameLength),
                          "e.g. \"SVGF\" or \"GBuffer_2\"", file);
        if (!names.insert(d.name).second)
            throwBadInput(where + "/name", "duplicate pass name '" + d.name + "'", "unique pass names",
                          "rename one of the passes", file);
        if (p.contains("device")) d.device = readDevice(p["device"], where + "/device", file);
        if (p.contains("params")) {
            if (!p["params"].is_object())
                throwBadInput(where + "/params", "'params' must be an object", "{\"name\": value, ...}", {}, file);
            d.params = p["params"];
        }
        if (p.contains("unconnected")) {
            const json& u = p["unconnected"];
            const bool ok = u.is_array() && std::all_of(u.begin(), u.end(), [](const json& v) { return v.is_string(); });
            if (!ok)
                throwBadInput(where + "/unconnected", "'unconnected' must be an array of input names",
                              "[\"direct\", \"indirect\"]", {}, file);
            for (const json& v : u) d.unconnected.push_back(v.get<std::string>());
        }
        g.passes.push_back(std::move(d));
    }
    if (root.contains("edges")) {
        const json& edges = root["edges"];
        if (!edges.is_array())
            throwBadInput("/edges", "'edges' must be an array", "[[\"A.out\", \"B.in\"], ...]", {}, file);
        for (size_t i = 0; i < edges.size(); ++i) {
            const std::string where = fmt::format("/edges/{}", i);
            const json& e = edges[i];
            if (!e.is_array() || e.size() != 2 || !e[0].is_string() || !e[1].is_string())
                throwBadInput(where, "an edge must be a pair of strings, got " + jsonExcerpt(e),
                              "[\"Source.output\", \"Destination.input\"]", {}, file);
            EdgeDesc ed;
            ed.src = parseChannelRef(e[0].get<std::string>(), where + "/0", file);
            ed.dst = parseChannelRef(e[1].get<std::string>(), where + "/1", file);
            if (ed.dst.prev)
                throwBadInput(where + "/1", "@prev is only allowed on an edge's source", "\"Pass.input\"",
                              "write [\"" + ed.src.pass + "." + ed.src.channel + "@prev\", \"" + ed.dst.pass + "." +
                                  ed.dst.channel + "\"]",
                              file);
            g.edges.push_back(std::move(ed));
        }
    }
    const json& outputs = require(root, "outputs", json::value_t::array, "an array of \"Pass.output\"", "", file);
    for (size_t i = 0; i < outputs.size(); ++i) {
        const std::string where = fmt::format("/outputs/{}", i);
        if (!outputs[i].is_string())
            throwBadInput(where, "an output must be a string", "\"Pass.output\"", {}, file);
        ChannelRef r = parseChannelRef(outputs[i].get<std::string>(), where, file);
        if (r.prev) throwBadInput(where, "a marked output cannot be @prev", "\"Pass.output\"", {}, file);
        g.outputs.push_back(std::move(r));
    }
    return g;
}

GraphDesc loadGraph(const std::filesystem::path& path) {
    std::error_code ec;
    if (!std::filesystem::exists(path, ec))
        throwBadInput({}, "graph file not found", "an existing .json graph file",
                      "check the path; the shipped graphs are in graphs/", path.string());
    return parseGraph(readInputFile(path, "graph file", "a .json graph file", uint64_t(16) << 20), path.string());
}

json graphToJson(const GraphDesc& g) {
    json root = json::object();
    root["loom_graph"] = kGraphFormatVersion;
    root["name"] = g.name;
    if (!g.device.empty()) root["device"] = g.device;
    json passes = json::array();
    for (const auto& p : g.passes) {
        json jp = {{"name", p.name}, {"type", p.type}};
        if (!p.params.empty()) jp["params"] = p.params;
        if (!p.unconnected.empty()) jp["unconnected"] = p.unconnected;
        if (!p.device.empty()) jp["device"] = p.device;
        passes.push_back(std::move(jp));
    }
    root["passes"] = std::move(passes);
    json edges = json::array();
    for (const auto& e : g.edges) edges.push_back(json::array({e.src.str(), e.dst.str()}));
    root["edges"] = std::move(edges);
    json outputs = json::array();
    for (const auto& o : g.outputs) outputs.push_back(o.str());
    root["outputs"] = std::move(outputs);
    return root;
}

void saveGraph(const GraphDesc& g, const std::filesystem::path& path) {
    writeFileAtomic(path, graphToJson(g).dump(2) + "\n");
}

}  // namespace loom
