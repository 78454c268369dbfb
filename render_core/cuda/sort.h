// Stage 3 of the CUDA core (sort.cu; mirrors cpu/sort.cpp).
// Raw device pointers and an explicit stream; every launcher checks its launch (CudaError).
#pragma once

#include <cstddef>
#include <cstdint>

#include "records.h"

namespace catgs::cuda::stages {

// Stage 3 (sort.cu): CUB radix sort of (key, value) pairs over the low `key_bits` bits. Sorts
// between the two halves of each double buffer; returns which half holds the result (0 or 1).
// sort_pairs_narrow: the same on 32-bit keys (the single sort's [tile | quantised depth], the
// depth-first sort's tile ids).
std::size_t sort_temp_bytes(uint64_t entries, int key_bits);
int sort_pairs(uint64_t* keys[2], uint32_t* values[2], uint64_t entries, int key_bits, void* temp,
               std::size_t temp_bytes, cudaStream_t stream);
std::size_t sort_narrow_temp_bytes(uint64_t entries, int key_bits);
int sort_pairs_narrow(uint32_t* keys[2], uint32_t* values[2], uint64_t entries, int key_bits, void* temp,
                      std::size_t temp_bytes, cudaStream_t stream);

}  // namespace catgs::cuda::stages
