// The host of laz-perf's WebAssembly module (laz_decoder.h): the module's imports (Emscripten's
// embind registrations, its C library's few system calls), its instantiation, and calls into
// the ChunkDecoder class it exports (laz-perf's cpp/emscripten/laz-perf.cpp: open(format,
// recordLength, pointer), getPoint(pointer)). embind's JavaScript side is replaced by the
// registrations it would receive: the raw invokers and contexts of the class's constructor and
// methods, called here through the module's function table.
#include "pipeline/io/laz_decoder.h"

#include <fmt/format.h>

#include <algorithm>
#include <cstring>
#include <mutex>
#include <string>
#include <type_traits>

extern "C" {
#include <lazperf.h>  // made by wasm2c from npm's laz-perf (pipeline/io/CMakeLists.txt)
}
#include "pipeline/io/laz_wasm_runtime.h"

namespace {

constexpr size_t kNameBytes = 64;
constexpr size_t kMessageBytes = 200;

// A method or constructor of an exported class: an index into the function table and, for a
// method, its context (where the member function pointer lies in the module's memory).
struct Binding {
  uint32_t invoker = 0;
  uint32_t context = 0;
  bool isFound = false;
};

}  // namespace

// The host state of one instance, passed to every import.
struct Z_env_instance_t {
  Z_lazperf_instance_t* module = nullptr;
  uint32_t classType = 0;  // embind's id of ChunkDecoder
  uint32_t destructor = 0;
  Binding constructor, open, getPoint;
  char message[kMessageBytes] = {};  // what the module threw last
  bool heapRefused = false;          // a growth of the memory was refused since the last open
};
struct Z_wasi_snapshot_preview1_instance_t {};

namespace {

// The C string at `address` of the module's memory, up to `limit` bytes ("" when it is not one).
void copyString(const wasm_rt_memory_t& memory, uint32_t address, char* to, size_t limit) {
  size_t n = 0;
  while (n + 1 < limit && uint64_t{address} + n < memory.size && memory.data[address + n] != 0) {
    const char c = char(memory.data[address + n]);
    to[n++] = c >= 32 && c < 127 ? c : '?';
  }
  to[n] = '\0';
}

bool nameIs(Z_env_instance_t* env, uint32_t address, const char* expected) {
  char name[kNameBytes];
  copyString(env->module->w2c_memory, address, name, sizeof name);
  return std::strcmp(name, expected) == 0;
}

void checkRange(const wasm_rt_memory_t& memory, uint32_t address, uint64_t bytes) {
  if (address + bytes > memory.size) wasm_rt_trap(WASM_RT_TRAP_OOB);
}

}  // namespace

// The module's imports. None leaves an object with a destructor behind when it traps.
extern "C" {

u32 Z_envZ___cxa_allocate_exception(Z_env_instance_t* env, u32 bytes) {
  return Z_lazperfZ_malloc(env->module, bytes);
}

// A C++ exception of the module: kept as a message (a std::runtime_error's what(): libc++ keeps
// a pointer to the text after the vtable pointer), then a trap that ends the call.
void Z_envZ___cxa_throw(Z_env_instance_t* env, u32 object, u32, u32) {
  const wasm_rt_memory_t& memory = env->module->w2c_memory;
  env->message[0] = '\0';
  if (uint64_t{object} + 8 <= memory.size) {
    uint32_t text = 0;
    std::memcpy(&text, memory.data + object + 4, 4);
    copyString(memory, text, env->message, sizeof env->message);
  }
  wasm_rt_trap(WASM_RT_TRAP_UNCAUGHT_EXCEPTION);
}

void Z_envZ__embind_register_class(Z_env_instance_t* env, u32 type, u32, u32, u32, u32, u32, u32,
                                   u32, u32, u32, u32 name, u32, u32 destructor) {
  if (!nameIs(env, name, "ChunkDecoder")) return;
  env->classType = type;
  env->destructor = destructor;
}

void Z_envZ__embind_register_class_constructor(Z_env_instance_t* env, u32 type, u32 argumentCount,
                                               u32, u32, u32 invoker, u32 constructor) {
  if (type == env->classType && env->classType != 0 && argumentCount == 1)
    env->constructor = {invoker, constructor, true};
}

void Z_envZ__embind_register_class_function(Z_env_instance_t* env, u32 type, u32 name, u32, u32,
                                            u32, u32 invoker, u32 context, u32) {
  if (type != env->classType || env->classType == 0) return;
  if (nameIs(env, name, "open")) env->open = {invoker, context, true};
  if (nameIs(env, name, "getPoint")) env->getPoint = {invoker, context, true};
}

void Z_envZ__embind_register_bigint(Z_env_instance_t*, u32, u32, u32, u32, u32, u32, u32) {}
void Z_envZ__embind_register_bool(Z_env_instance_t*, u32, u32, u32, u32, u32) {}
void Z_envZ__embind_register_emval(Z_env_instance_t*, u32, u32) {}
void Z_envZ__embind_register_float(Z_env_instance_t*, u32, u32, u32) {}
void Z_envZ__embind_register_integer(Z_env_instance_t*, u32, u32, u32, u32, u32) {}
void Z_envZ__embind_register_memory_view(Z_env_instance_t*, u32, u32, u32) {}
void Z_envZ__embind_register_std_string(Z_env_instance_t*, u32, u32) {}
void Z_envZ__embind_register_std_wstring(Z_env_instance_t*, u32, u32, u32) {}
void Z_envZ__embind_register_void(Z_env_instance_t*, u32, u32) {}

void Z_envZ_abort(Z_env_instance_t*) { wasm_rt_trap(WASM_RT_TRAP_UNREACHABLE); }

void Z_envZ_emscripten_memcpy_big(Z_env_instance_t* env, u32 to, u32 from, u32 bytes) {
  wasm_rt_memory_t& memory = env->module->w2c_memory;
  checkRange(memory, to, bytes);
  checkRange(memory, from, bytes);
  std::memmove(memory.data + to, memory.data + from, bytes);
}

// Emscripten's malloc asks for a memory of `bytes` in all: 1 when it grew, 0 when it cannot. It
// asks for little more than it needs each time, so the memory grows by half at least (as
// Emscripten's own JavaScript grows it): a growth copies the memory.
u32 Z_envZ_emscripten_resize_heap(Z_env_instance_t* env, u32 bytes) {
  wasm_rt_memory_t& memory = env->module->w2c_memory;
  const uint64_t needed = (uint64_t{bytes} + 65535) / 65536;
  if (needed <= memory.pages) return 1;
  const uint64_t pages =
      std::min<uint64_t>(std::max<uint64_t>(needed, memory.pages * 3 / 2), memory.max_pages);
  if (pages >= needed && wasm_rt_grow_memory(&memory, uint32_t(pages - memory.pages)) != UINT32_MAX)
    return 1;
  if (wasm_rt_grow_memory(&memory, uint32_t(needed - memory.pages)) != UINT32_MAX) return 1;
  env->heapRefused = true;
  return 0;
}

u32 Z_envZ_strftime_l(Z_env_instance_t*, u32, u32, u32, u32, u32) { return 0; }

// WASI: no environment, no files; what the module prints (it should print nothing) is dropped.
u32 Z_wasi_snapshot_preview1Z_environ_get(Z_wasi_snapshot_preview1_instance_t*, u32, u32) {
  return 0;
}
u32 Z_wasi_snapshot_preview1Z_environ_sizes_get(Z_wasi_snapshot_preview1_instance_t*, u32, u32) {
  return 52;  // WASI ENOSYS
}
u32 Z_wasi_snapshot_preview1Z_fd_close(Z_wasi_snapshot_preview1_instance_t*, u32) { return 8; }
u32 Z_wasi_snapshot_preview1Z_fd_seek(Z_wasi_snapshot_preview1_instance_t*, u32, u32, u32, u32,
                                      u32) {
  return 8;  // WASI EBADF
}
u32 Z_wasi_snapshot_preview1Z_fd_write(Z_wasi_snapshot_preview1_instance_t*, u32, u32, u32, u32) {
  return 8;
}

}  // extern "C"

namespace iso::io {
namespace {

// Bytes of zeros after a chunk's copy: the decoder reads its input through a bare pointer.
constexpr size_t kPadding = 64;
// Records decoded into the module's memory before they are copied out: 4,096, or fewer when
// their extra bytes make them long (a record takes at most 65,535), within 1 MiB.
size_t sliceRecords(size_t recordLength) {
  return std::clamp<size_t>((size_t{1} << 20) / std::max<size_t>(recordLength, 1), 1, 4096);
}
// What a chunk's decoding may take of the module's memory past the chunk's copy and the decoded
// records: laz-perf keeps the layers of a point format 6-8 chunk in buffers of the sizes the chunk
// declares (together at most the chunk's bytes; twice that is allowed), and its models take a few
// MiB. A chunk whose declared sizes are damaged fails to open instead of taking up to the module's
// whole memory (1 GiB) for a few bytes of input.
constexpr size_t kDecodingHeadroom = size_t{16} << 20;

// Signatures of the functions called through the table, as the compiled module registers them.
struct FunctionTypes {
  uint32_t constructor, open, getPoint;
};

const FunctionTypes& functionTypes() {
  static const FunctionTypes types = [] {
    Z_lazperf_init_module();
    constexpr wasm_rt_type_t i = WASM_RT_I32;
    return FunctionTypes{wasm_rt_register_func_type(1, 1, i, i),
                         wasm_rt_register_func_type(5, 0, i, i, i, i, i),
                         wasm_rt_register_func_type(3, 0, i, i, i)};
  }();
  return types;
}

// Run f() so that a trap of the module returns here: the trap's code, 0 when none.
template <typename F>
int guarded(F& f) {
  return isoWasmCall([](void* call) { (*static_cast<F*>(call))(); }, &f);
}

// An instantiated module, freed with its owner.
struct Module {
  Z_lazperf_instance_t instance{};
  bool isLive = false;
  Module() = default;
  Module(const Module&) = delete;
  Module& operator=(const Module&) = delete;
  ~Module() {
    if (isLive) Z_lazperf_free(&instance);
  }
};

}  // namespace

struct LazChunkDecoder::Instance {
  Z_env_instance_t env;
  Z_wasi_snapshot_preview1_instance_t wasi;
  Module owner;
  Z_lazperf_instance_t& module = owner.instance;
  uint32_t decoder = 0;   // the ChunkDecoder object
  uint32_t maxPages = 0;  // the module's own limit on its memory
  uint32_t input = 0, output = 0;
  size_t inputCapacity = 0, outputCapacity = 0;
  bool isBroken = false;

  Instance() {
    const FunctionTypes& types = functionTypes();
    env.module = &module;
    Z_lazperf_instantiate(&module, &env, &wasi);
    owner.isLive = true;
    maxPages = module.w2c_memory.max_pages;
    auto start = [&] {
      Z_lazperfZ_emscripten_stack_init(&module);
      Z_lazperfZ___wasm_call_ctors(&module);
    };
    check(guarded(start), "starting");
    if (!env.constructor.isFound || !env.open.isFound || !env.getPoint.isFound)
      fail("the module does not export laz-perf's ChunkDecoder");
    const auto construct = function<u32 (*)(void*, u32)>(env.constructor, types.constructor);
    auto create = [&] { decoder = construct.call(construct.instance, env.constructor.context); };
    check(guarded(create), "starting");
  }
  Instance(const Instance&) = delete;
  Instance& operator=(const Instance&) = delete;

  template <typename Pointer>
  struct Function {
    Pointer call;
    void* instance;
  };

  // The function a binding invokes, checked against the signature the host calls it with.
  template <typename Pointer>
  Function<Pointer> function(const Binding& binding, uint32_t type) const {
    const wasm_rt_funcref_table_t& table = module.w2c___indirect_function_table;
    if (binding.invoker >= table.size || table.data[binding.invoker].func == nullptr ||
        table.data[binding.invoker].func_type != type)
      fail("a binding of laz-perf's ChunkDecoder has another signature");
    const wasm_rt_funcref_t& entry = table.data[binding.invoker];
    return {reinterpret_cast<Pointer>(entry.func), entry.module_instance};
  }

  // A buffer of at least `bytes` in the module's memory at `address` (allocated anew if smaller).
  void reserve(uint32_t& address, size_t& capacity, size_t bytes) {
    if (capacity >= bytes) return;
    auto allocate = [&] {
      if (address != 0) Z_lazperfZ_free(&module, address);
      address = Z_lazperfZ_malloc(&module, uint32_t(bytes));
    };
    capacity = 0;
    check(guarded(allocate), "allocating");
    if (address == 0) fail(fmt::format("{} bytes do not fit the decoder's memory", bytes));
    capacity = bytes;
  }

  // Let the memory grow no further than `bytes` past its size now (nor past the module's limit).
  void limitGrowth(uint64_t bytes) {
    wasm_rt_memory_t& memory = module.w2c_memory;
    const uint64_t pages = (uint64_t{memory.size} + bytes + 65535) / 65536;
    memory.max_pages = uint32_t(std::clamp<uint64_t>(pages, memory.pages, maxPages));
    env.heapRefused = false;
  }

  void check(int trap, const char* doing) {
    if (trap == 0) return;
    isBroken = true;
    std::string what = wasm_rt_strerror(wasm_rt_trap_t(trap));
    if (trap == WASM_RT_TRAP_UNCAUGHT_EXCEPTION)
      what = env.message[0] != '\0' ? std::string("laz-perf: ") + env.message : "an exception";
    if (env.heapRefused)
      what = fmt::format(
          "it asked for more than the {} MiB of memory a chunk of its size may take: "
          "the sizes the chunk declares are damaged",
          module.w2c_memory.max_pages / 16);
    fail(fmt::format("the LAZ decoder failed {} ({})", doing, what));
  }

  [[noreturn]] static void fail(const std::string& reason) { throw LazDecodeError(reason); }
};

bool hasLazDecoder() { return true; }

LazChunkDecoder::LazChunkDecoder() : instance_(std::make_unique<Instance>()) {}
LazChunkDecoder::~LazChunkDecoder() = default;

void LazChunkDecoder::open(int format, size_t recordLength, std::span<const std::byte> chunk) {
  if (chunk.size() > kMaxLazChunkBytes)
    throw LazDecodeError(fmt::format("a chunk of {} bytes is larger than the decoder takes ({})",
                                     chunk.size(), kMaxLazChunkBytes));
  if (instance_->isBroken) instance_ = std::make_unique<Instance>();
  Instance& w = *instance_;
  w.limitGrowth(uint64_t{2} * (chunk.size() + kPadding) +
                sliceRecords(recordLength) * recordLength + kDecodingHeadroom);
  w.reserve(w.input, w.inputCapacity, chunk.size() + kPadding);
  std::byte* input = reinterpret_cast<std::byte*>(w.module.w2c_memory.data + w.input);
  std::copy(chunk.begin(), chunk.end(), input);
  std::fill_n(input + chunk.size(), kPadding, std::byte{0});
  const auto openChunk =
      w.function<void (*)(void*, u32, u32, u32, u32, u32)>(w.env.open, functionTypes().open);
  auto call = [&] {
    openChunk.call(openChunk.instance, w.env.open.context, w.decoder, u32(format),
                   u32(recordLength), w.input);
  };
  w.check(guarded(call), "opening a chunk");
  format_ = format;
  recordLength_ = recordLength;
}

size_t LazChunkDecoder::memoryBytes() const { return instance_->module.w2c_memory.size; }

void LazChunkDecoder::decode(size_t count, std::byte* out) {
  Instance& w = *instance_;
  if (w.isBroken || recordLength_ == 0) throw LazDecodeError("no chunk is open");
  const size_t records = sliceRecords(recordLength_);
  w.reserve(w.output, w.outputCapacity, std::min(count, records) * recordLength_);
  const auto getPoint =
      w.function<void (*)(void*, u32, u32, u32)>(w.env.getPoint, functionTypes().getPoint);
  for (size_t done = 0; done < count;) {
    const size_t slice = std::min(count - done, records);
    auto call = [&] {
      for (size_t i = 0; i < slice; ++i)
        getPoint.call(getPoint.instance, w.env.getPoint.context, w.decoder,
                      w.output + u32(i * recordLength_));
    };
    w.check(guarded(call), "decoding a chunk");
    std::memcpy(out + done * recordLength_, w.module.w2c_memory.data + w.output,
                slice * recordLength_);
    done += slice;
  }
}

}  // namespace iso::io
