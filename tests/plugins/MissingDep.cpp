// Links against a library the loader cannot find: dlopen must fail with a clear error.
#include "loom/Plugin.h"

extern "C" int loomHiddenDependency();

namespace {
class MissingDep final : public loom::RenderPass {
public:
    void reflect(loom::Reflection& r, const loom::CompileInfo&) const override { r.output("dst", loom::Format::R32F); }
    void execute(loom::PassContext&) override { (void)loomHiddenDependency(); }
};
}  // namespace

LOOM_DEFINE_PLUGIN(r) { r.registerPass<MissingDep>("MissingDep", "needs a missing library"); }
