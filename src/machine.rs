//! The machine a benchmark or a run measured its speed on: the CPU model and the
//! widest vector instruction set it offers. Every speed figure depends on both
//! (issue 17: Mitsuba's LLVM back end runs 8 paths per instruction with AVX2 and 16
//! with AVX-512), so `camsim bench` prints them and a run's manifest keeps them.

/// CPU model and vector width of this machine.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Cpu {
    /// The processor's brand string (e.g. "AMD EPYC"), or the architecture when the
    /// processor does not report one.
    pub model: String,
    /// The widest vector extension the CPU and the OS enable: `avx512f`, `avx2+fma`
    /// or `sse` on x86-64 (SSE2 is its baseline), `neon` on 64-bit ARM, else `scalar`.
    pub vector: &'static str,
}

impl std::fmt::Display for Cpu {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{} ({})", self.model, self.vector)
    }
}

/// This machine's CPU (brand string from CPUID on x86; the vector width from the
/// features the running CPU and OS support, not those the binary was built for).
pub fn cpu() -> Cpu {
    Cpu {
        model: model().unwrap_or_else(|| std::env::consts::ARCH.to_string()),
        vector: vector_width(),
    }
}

#[cfg(any(target_arch = "x86", target_arch = "x86_64"))]
fn model() -> Option<String> {
    let brand = raw_cpuid::CpuId::new().get_processor_brand_string()?;
    let s = brand
        .as_str()
        .split_whitespace()
        .collect::<Vec<_>>()
        .join(" ");
    (!s.is_empty()).then_some(s)
}

#[cfg(not(any(target_arch = "x86", target_arch = "x86_64")))]
fn model() -> Option<String> {
    None
}

#[cfg(any(target_arch = "x86", target_arch = "x86_64"))]
fn vector_width() -> &'static str {
    if std::arch::is_x86_feature_detected!("avx512f") {
        "avx512f"
    } else if std::arch::is_x86_feature_detected!("avx2")
        && std::arch::is_x86_feature_detected!("fma")
    {
        "avx2+fma"
    } else {
        "sse"
    }
}

#[cfg(target_arch = "aarch64")]
fn vector_width() -> &'static str {
    "neon"
}

#[cfg(not(any(target_arch = "x86", target_arch = "x86_64", target_arch = "aarch64")))]
fn vector_width() -> &'static str {
    "scalar"
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The model is non-empty, and on Linux x86 it is the kernel's own reading
    /// of the same CPUID brand string (`/proc/cpuinfo` "model name").
    #[test]
    fn cpu_model_matches_the_kernel() {
        let c = cpu();
        assert!(!c.model.is_empty());
        assert!(["avx512f", "avx2+fma", "sse", "neon", "scalar"].contains(&c.vector));
        if cfg!(any(target_arch = "x86", target_arch = "x86_64"))
            && let Ok(info) = std::fs::read_to_string("/proc/cpuinfo")
            && let Some(line) = info.lines().find(|l| l.starts_with("model name"))
        {
            let kernel = line.split_once(':').unwrap().1;
            let kernel = kernel.split_whitespace().collect::<Vec<_>>().join(" ");
            assert_eq!(c.model, kernel);
            let flags = info
                .lines()
                .find(|l| l.starts_with("flags"))
                .unwrap_or_default();
            let has = |f: &str| flags.split_whitespace().any(|x| x == f);
            let expect = if has("avx512f") {
                "avx512f"
            } else if has("avx2") && has("fma") {
                "avx2+fma"
            } else {
                "sse"
            };
            assert_eq!(c.vector, expect);
        }
        assert_eq!(c.to_string(), format!("{} ({})", c.model, c.vector));
    }
}
