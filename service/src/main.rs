/// mimalloc instead of glibc's malloc: a Monte Carlo job allocates one sketch per group, bin and
/// metric on each compute thread, and glibc grew its per-thread heaps a page range at a time (2378
/// `mprotect` calls for one 2000 x 500 job); mimalloc's segments made that job 10 % faster, same
/// bits (docs/performance.md).
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

fn main() -> std::process::ExitCode {
    keep_freed_c_memory();
    bouncewear::cli::main()
}

/// glibc's malloc still serves the C code of the bundled SQLite, whose statements take buffers the
/// size of what they read and write: a small job's Result put back from its 115 rows goes through
/// 100-250 kB of them. glibc starts by mapping each block of 128 kB or more on its own and giving
/// free memory at the top of a thread's heap back to the kernel, so the next statement takes it
/// again, zeroed, a page fault at a time: 82 faults for each read of a small Result, a third of its
/// time. Its thresholds rise to 32 MiB (map) and 64 MiB (give back) only once a block that large
/// has been freed, such as a 1000-bin job's 17 MB Result; they are set there from the start, so a
/// server that has only served small jobs runs as one that has served a large one (5 faults a
/// read; docs/performance-history.md).
fn keep_freed_c_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: mallopt only sets two of glibc's malloc parameters; it runs first in `main`, before
    // any other thread exists.
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, 32 << 20);
        libc::mallopt(libc::M_TRIM_THRESHOLD, 64 << 20);
    }
}
