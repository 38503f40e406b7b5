// A shared library without Loom's entry points.
extern "C" int somethingElse() { return 1; }
