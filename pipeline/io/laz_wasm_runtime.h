/* The host side of the runtime of C compiled from WebAssembly by wasm2c (laz_wasm_runtime.c). */
#pragma once

#include <wasm-rt.h>

#ifdef __cplusplus
extern "C" {
#endif

/* Call call(argument) so that a trap of the WebAssembly code it runs returns here: 0 when it
 * returned, else the wasm_rt_trap_t code. Only C frames may lie between this call and the trap
 * (longjmp runs no destructors). Nests, per thread. */
int isoWasmCall(void (*call)(void*), void* argument);

#ifdef __cplusplus
}
#endif
