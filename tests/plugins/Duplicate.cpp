// Registers a type the test passes already provide ("Constant").
#include "loom/Plugin.h"

namespace {
class Dup final : public loom::RenderPass {
public:
    void reflect(loom::Reflection& r, const loom::CompileInfo&) const override { r.output("dst", loom::Format::R32F); }
    void execute(loom::PassContext&) override {}
};
}  // namespace

LOOM_DEFINE_PLUGIN(r) { r.registerPass<Dup>("Constant", "duplicate of the test pass"); }
