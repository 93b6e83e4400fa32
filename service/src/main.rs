/// mimalloc instead of glibc's malloc: a Monte Carlo job allocates one sketch per group, bin and
/// metric on each compute thread, and glibc grew its per-thread heaps a page range at a time (2378
/// `mprotect` calls for one 2000 x 500 job); mimalloc's segments made that job 10 % faster, same
/// bits (docs/performance.md).
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

fn main() -> std::process::ExitCode {
    bouncewear::cli::main()
}
