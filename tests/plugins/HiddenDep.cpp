// A library the MissingDep plugin links against; it is kept out of the loader's path.
extern "C" int loomHiddenDependency() { return 42; }
