// Proves the sanitizer harness (run.sh) fails a test on a report from a process the test started
// and never waited for: `race` is a data race (TSan), `leak` a leak (LSan), `overflow` a heap
// overflow (ASan). Each exits 0 when its sanitizer does not stop it, as a careless child would.
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <thread>

namespace {

int shared_counter = 0;  // written by two threads without a lock: the race
void* volatile leaked = nullptr;

}  // namespace

int main(int argc, char** argv) {
  const std::string what = argc > 1 ? argv[1] : "";
  if (what == "race") {
    std::thread t([] { shared_counter += 1; });
    shared_counter += 2;
    t.join();
  } else if (what == "leak") {
    leaked = std::malloc(64);
    leaked = nullptr;
  } else if (what == "overflow") {
    char* volatile p = static_cast<char*>(std::malloc(8));
    std::memset(p, 0, 9);
    std::free(p);
  } else {
    std::fprintf(stderr, "usage: sanitizer_selftest race|leak|overflow\n");
    return 2;
  }
  std::printf("sanitizer_selftest %s: done, %d\n", what.c_str(), shared_counter);
  return 0;
}
