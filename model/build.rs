//! Whether this build compiles the AVX-512 kernel (`cfg(avx512_kernel)`, see
//! `src/montecarlo/kernel.rs`): where it can run, on an x86_64 host with AVX-512F, or when
//! `BOUNCEWEAR_ALL_KERNELS` is set, in every profile. The 32-lane AVX-512 kernel is more than half
//! of the model's build: on a 2-core EPYC VM, which could never run it, its library took 125 s
//! with it and 45 s without (`cargo build -p bouncewear-model --features openapi --lib`, test
//! profile; 161 s against 90 s in release). A binary built without it runs the AVX2 kernel on an
//! AVX-512 CPU, with the same bits: one meant for other machines is built with
//! `BOUNCEWEAR_ALL_KERNELS=1`, as the Dockerfile does.

fn main() {
    println!("cargo::rustc-check-cfg=cfg(avx512_kernel)");
    println!("cargo::rerun-if-changed=build.rs");
    println!("cargo::rerun-if-env-changed=BOUNCEWEAR_ALL_KERNELS");
    let x86_64 = std::env::var("CARGO_CFG_TARGET_ARCH").is_ok_and(|arch| arch == "x86_64");
    let asked = std::env::var_os("BOUNCEWEAR_ALL_KERNELS").is_some();
    if x86_64 && (asked || host_runs_avx512()) {
        println!("cargo::rustc-cfg=avx512_kernel");
    }
}

/// Whether the machine building runs AVX-512F (and so the tests built here can run the kernel).
fn host_runs_avx512() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx512f")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}
