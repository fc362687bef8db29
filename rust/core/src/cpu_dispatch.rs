//! One function compiled for the vector units a CPU may have, the copy it runs chosen at run
//! time: the core's hot loops are written once, as plain loops, and the compiler vectorises each
//! copy for AVX-512 (8 f64 an instruction), AVX2 (4) or the x86-64 baseline, SSE2 (2), so a
//! wheel built for any x86-64 runs everywhere and fast where it can.

/// `fn name(args) -> ret = body, avx512 name_avx512, avx2 name_avx2;` defines `name`, which
/// runs `body(args)` compiled with AVX-512F (and AVX2, FMA), else with AVX2 and FMA, else as
/// built, by what the CPU supports; and the two unsafe copies under the names given (callable
/// where the CPU is known to support their features, as tests comparing the copies do). FMA is
/// only allowed, never used unasked: Rust does not contract a * b + c, so all copies round alike.
macro_rules! compiled_per_cpu {
    (
        $(#[$doc:meta])*
        $vis:vis fn $name:ident($($arg:ident: $ty:ty),* $(,)?) -> $ret:ty
        = $body:ident, avx512 $avx512:ident, avx2 $avx2:ident;
    ) => {
        $(#[$doc])*
        $vis fn $name($($arg: $ty),*) -> $ret {
            #[cfg(target_arch = "x86_64")]
            if std::arch::is_x86_feature_detected!("avx512f") {
                // SAFETY: the CPU supports AVX-512F, checked just above.
                return unsafe { $avx512($($arg),*) };
            }
            #[cfg(target_arch = "x86_64")]
            if std::arch::is_x86_feature_detected!("avx2")
                && std::arch::is_x86_feature_detected!("fma")
            {
                // SAFETY: the CPU supports AVX2 and FMA, checked just above.
                return unsafe { $avx2($($arg),*) };
            }
            $body($($arg),*)
        }

        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = "avx2,fma")]
        unsafe fn $avx2($($arg: $ty),*) -> $ret {
            $body($($arg),*)
        }

        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = "avx512f,avx2,fma")]
        unsafe fn $avx512($($arg: $ty),*) -> $ret {
            $body($($arg),*)
        }
    };
}

pub(crate) use compiled_per_cpu;
