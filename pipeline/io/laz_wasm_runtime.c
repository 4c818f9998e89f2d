/* The runtime that C compiled from WebAssembly by wabt's wasm2c calls (the functions wasm-rt.h
 * declares), for laz-perf's LAZ decoder (laz_decoder.cpp). wabt's own runtime jumps back from a
 * trap through one global jmp_buf and catches out-of-bounds accesses with a SIGSEGV handler;
 * this one is for code compiled with explicit bounds checks (WASM_RT_MEMCHECK_SIGNAL_HANDLER 0,
 * no call-depth counting) and returns from a trap to the innermost isoWasmCall of the trapping
 * thread, so that instances may run on several threads at once (one thread an instance). */
#include "pipeline/io/laz_wasm_runtime.h"

#include <pthread.h>
#include <stdarg.h>

enum {
  kPageBytes = 65536,
  /* An instance's memory stays below this many pages (1 GiB), whatever the module allows: it
   * holds one chunk, compressed, and a slice of its decoded records (laz_decoder.h). */
  kMaxPages = 16384,
  kMaxFuncTypes = 256,
  kMaxTypeValues = 32
};

static _Thread_local jmp_buf* unwindTarget;

bool wasm_rt_is_initialized(void) { return true; }
void wasm_rt_init(void) {}
void wasm_rt_free(void) {}

void wasm_rt_trap(wasm_rt_trap_t code) {
  if (unwindTarget == NULL) abort(); /* a trap outside isoWasmCall: a bug of the host */
  longjmp(*unwindTarget, (int)code);
}

const char* wasm_rt_strerror(wasm_rt_trap_t trap) {
  switch (trap) {
    case WASM_RT_TRAP_NONE: return "no error";
    case WASM_RT_TRAP_OOB: return "out-of-bounds memory access";
    case WASM_RT_TRAP_INT_OVERFLOW: return "integer overflow";
    case WASM_RT_TRAP_DIV_BY_ZERO: return "integer division by zero";
    case WASM_RT_TRAP_INVALID_CONVERSION: return "invalid conversion";
    case WASM_RT_TRAP_UNREACHABLE: return "unreachable code or an exception";
    case WASM_RT_TRAP_CALL_INDIRECT: return "invalid indirect call";
    default: return "trap";
  }
}

int isoWasmCall(void (*call)(void*), void* argument) {
  jmp_buf target;
  jmp_buf* const outer = unwindTarget;
  const int code = setjmp(target);
  if (code == 0) {
    unwindTarget = &target;
    call(argument);
  }
  unwindTarget = outer;
  return code;
}

/* Function types, registered when a module is initialized: equal signatures get equal
 * indices, which the compiled code compares at indirect calls. */
static struct {
  uint32_t params, results;
  wasm_rt_type_t values[kMaxTypeValues];
} funcTypes[kMaxFuncTypes];
static uint32_t funcTypeCount;
static pthread_mutex_t funcTypeLock = PTHREAD_MUTEX_INITIALIZER;

uint32_t wasm_rt_register_func_type(uint32_t params, uint32_t results, ...) {
  wasm_rt_type_t values[kMaxTypeValues];
  const uint32_t count = params + results;
  if (count > kMaxTypeValues) abort();
  va_list list;
  va_start(list, results);
  for (uint32_t i = 0; i < count; ++i) values[i] = (wasm_rt_type_t)va_arg(list, int);
  va_end(list);
  pthread_mutex_lock(&funcTypeLock);
  uint32_t index = 0;
  while (index < funcTypeCount &&
         (funcTypes[index].params != params || funcTypes[index].results != results ||
          memcmp(funcTypes[index].values, values, count * sizeof values[0]) != 0))
    ++index;
  if (index == funcTypeCount) {
    if (funcTypeCount == kMaxFuncTypes) abort();
    funcTypes[index].params = params;
    funcTypes[index].results = results;
    memcpy(funcTypes[index].values, values, count * sizeof values[0]);
    ++funcTypeCount;
  }
  pthread_mutex_unlock(&funcTypeLock);
  return index + 1; /* 0 is a null function's type */
}

void wasm_rt_allocate_memory(wasm_rt_memory_t* memory, uint32_t initialPages,
                             uint32_t maxPages) {
  if (initialPages > kMaxPages) abort();
  memory->data = calloc((size_t)initialPages * kPageBytes + 1, 1);
  if (memory->data == NULL) abort();
  memory->pages = initialPages;
  memory->max_pages = maxPages < kMaxPages ? maxPages : kMaxPages;
  memory->size = initialPages * kPageBytes;
}

uint32_t wasm_rt_grow_memory(wasm_rt_memory_t* memory, uint32_t delta) {
  const uint32_t oldPages = memory->pages;
  if (delta == 0) return oldPages;
  if (delta > memory->max_pages - oldPages) return UINT32_MAX;
  const size_t oldBytes = (size_t)oldPages * kPageBytes;
  const size_t newBytes = (size_t)(oldPages + delta) * kPageBytes;
  uint8_t* data = realloc(memory->data, newBytes);
  if (data == NULL) return UINT32_MAX;
  memset(data + oldBytes, 0, newBytes - oldBytes);
  memory->data = data;
  memory->pages = oldPages + delta;
  memory->size = (uint32_t)newBytes;
  return oldPages;
}

void wasm_rt_free_memory(wasm_rt_memory_t* memory) {
  free(memory->data);
  memory->data = NULL;
}

void wasm_rt_allocate_funcref_table(wasm_rt_funcref_table_t* table, uint32_t elements,
                                    uint32_t maxElements) {
  table->data = calloc((size_t)elements + 1, sizeof(wasm_rt_funcref_t));
  if (table->data == NULL) abort();
  table->size = elements;
  table->max_size = maxElements;
}

void wasm_rt_free_funcref_table(wasm_rt_funcref_table_t* table) {
  free(table->data);
  table->data = NULL;
}
