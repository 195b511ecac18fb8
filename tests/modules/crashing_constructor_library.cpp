// A shared library that is no Reflex plugin (no entry points) and whose static constructor writes
// through a null pointer: reflex_behavior --plugin crashes in dlopen, before the "not a Reflex module
// plugin" check can run. It shows that loading a plugin is running its code (modules/README.md), and
// that the crash names the file.
namespace {

struct WritesThroughNull {
  WritesThroughNull() {
    volatile int* volatile nowhere = nullptr;  // volatile: the compiler may not prove it null and drop the write
    *nowhere = 1;
  }
};
const WritesThroughNull at_load;

}  // namespace
