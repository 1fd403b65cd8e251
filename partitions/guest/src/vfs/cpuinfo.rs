//! `/proc/cpuinfo`: a block per CPU of the guest in Linux's x86 format, from the processor's
//! CPUID (every CPU of a machine is alike here). Scripts count its `processor` lines
//! (`grep -c ^processor`) and read `model name`, `flags` (`grep -q avx2`) and `vendor_id`;
//! the guest has no frequency of its own to show beyond what CPUID leaf 0x16 says, and no
//! `bogomips` (Linux's boot-time delay loop).

use core::fmt::Write;

/// What `/proc/cpuinfo` shows of the processor.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CpuId {
    pub vendor: [u8; 12],
    /// The brand string (leaves 0x8000_0002..=4), NUL-padded; all NULs: none.
    pub brand: [u8; 48],
    /// Leaf 1's EAX (signature), EBX, ECX and EDX.
    pub signature: u32,
    pub ebx1: u32,
    pub ecx1: u32,
    pub edx1: u32,
    /// The highest basic leaf.
    pub level: u32,
    /// Leaf 7's EBX, leaf 0x8000_0001's ECX and EDX.
    pub ebx7: u32,
    pub ecx_ext: u32,
    pub edx_ext: u32,
    /// Leaf 0x8000_0008's EAX (address sizes), 0 without it.
    pub sizes: u32,
    /// Leaf 0x16's base frequency in MHz, 0 without it.
    pub mhz: u32,
}

impl Default for CpuId {
    fn default() -> Self {
        Self {
            vendor: [0; 12],
            brand: [0; 48],
            signature: 0,
            ebx1: 0,
            ecx1: 0,
            edx1: 0,
            level: 0,
            ebx7: 0,
            ecx_ext: 0,
            edx_ext: 0,
            sizes: 0,
            mhz: 0,
        }
    }
}

impl CpuId {
    /// The processor's, as CPUID answers here (the guest runs on the machine's CPUs).
    #[cfg(target_arch = "x86_64")]
    pub fn read() -> Self {
        use core::arch::x86_64::__cpuid;
        let zero = __cpuid(0);
        let mut id = CpuId {
            level: zero.eax,
            ..CpuId::default()
        };
        for (i, word) in [zero.ebx, zero.edx, zero.ecx].into_iter().enumerate() {
            id.vendor[4 * i..4 * i + 4].copy_from_slice(&word.to_le_bytes());
        }
        let one = __cpuid(1);
        (id.signature, id.ebx1, id.ecx1, id.edx1) = (one.eax, one.ebx, one.ecx, one.edx);
        if id.level >= 7 {
            id.ebx7 = __cpuid(7).ebx;
        }
        if id.level >= 0x16 {
            id.mhz = __cpuid(0x16).eax & 0xffff;
        }
        let ext = __cpuid(0x8000_0000).eax;
        if ext >= 0x8000_0001 {
            let r = __cpuid(0x8000_0001);
            (id.ecx_ext, id.edx_ext) = (r.ecx, r.edx);
        }
        if ext >= 0x8000_0004 {
            for (i, leaf) in (0x8000_0002..=0x8000_0004).enumerate() {
                let r = __cpuid(leaf);
                for (j, word) in [r.eax, r.ebx, r.ecx, r.edx].into_iter().enumerate() {
                    let at = 16 * i + 4 * j;
                    id.brand[at..at + 4].copy_from_slice(&word.to_le_bytes());
                }
            }
        }
        if ext >= 0x8000_0008 {
            id.sizes = __cpuid(0x8000_0008).eax;
        }
        id
    }

    #[cfg(not(target_arch = "x86_64"))]
    pub fn read() -> Self {
        CpuId::default()
    }

    /// Family, model and stepping as Linux computes them from the signature.
    fn family_model_stepping(&self) -> (u32, u32, u32) {
        let s = self.signature;
        let mut family = s >> 8 & 0xf;
        if family == 0xf {
            family += s >> 20 & 0xff;
        }
        let mut model = s >> 4 & 0xf;
        if family >= 6 {
            model += (s >> 16 & 0xf) << 4;
        }
        (family, model, s & 0xf)
    }
}

/// Linux's flag names of the CPUID bits it shows, in its order: leaf 1 EDX, 0x8000_0001
/// EDX, leaf 1 ECX, 0x8000_0001 ECX, leaf 7 EBX (the common ones; others are left out).
const EDX1: &[(u32, &str)] = &[
    (0, "fpu"),
    (1, "vme"),
    (2, "de"),
    (3, "pse"),
    (4, "tsc"),
    (5, "msr"),
    (6, "pae"),
    (7, "mce"),
    (8, "cx8"),
    (9, "apic"),
    (11, "sep"),
    (12, "mtrr"),
    (13, "pge"),
    (14, "mca"),
    (15, "cmov"),
    (16, "pat"),
    (17, "pse36"),
    (19, "clflush"),
    (21, "dts"),
    (22, "acpi"),
    (23, "mmx"),
    (24, "fxsr"),
    (25, "sse"),
    (26, "sse2"),
    (27, "ss"),
    (28, "ht"),
    (29, "tm"),
    (31, "pbe"),
];
const EDX_EXT: &[(u32, &str)] = &[
    (11, "syscall"),
    (20, "nx"),
    (22, "mmxext"),
    (25, "fxsr_opt"),
    (26, "pdpe1gb"),
    (27, "rdtscp"),
    (29, "lm"),
];
const ECX1: &[(u32, &str)] = &[
    (0, "pni"),
    (1, "pclmulqdq"),
    (3, "monitor"),
    (5, "vmx"),
    (7, "est"),
    (9, "ssse3"),
    (12, "fma"),
    (13, "cx16"),
    (17, "pcid"),
    (19, "sse4_1"),
    (20, "sse4_2"),
    (21, "x2apic"),
    (22, "movbe"),
    (23, "popcnt"),
    (24, "tsc_deadline_timer"),
    (25, "aes"),
    (26, "xsave"),
    (28, "avx"),
    (29, "f16c"),
    (30, "rdrand"),
    (31, "hypervisor"),
];
const ECX_EXT: &[(u32, &str)] = &[
    (0, "lahf_lm"),
    (1, "cmp_legacy"),
    (2, "svm"),
    (5, "abm"),
    (6, "sse4a"),
    (7, "misalignsse"),
    (8, "3dnowprefetch"),
];
const EBX7: &[(u32, &str)] = &[
    (0, "fsgsbase"),
    (3, "bmi1"),
    (4, "hle"),
    (5, "avx2"),
    (7, "smep"),
    (8, "bmi2"),
    (9, "erms"),
    (10, "invpcid"),
    (11, "rtm"),
    (16, "avx512f"),
    (18, "rdseed"),
    (19, "adx"),
    (20, "smap"),
    (23, "clflushopt"),
    (24, "clwb"),
    (29, "sha_ni"),
];

/// `/proc/cpuinfo` of a guest with CPUs `cpus` (bit n: CPU n) on processor `id`.
pub fn write(w: &mut impl Write, cpus: u64, id: &CpuId) {
    let vendor = core::str::from_utf8(&id.vendor).unwrap_or("unknown");
    let brand = core::str::from_utf8(&id.brand)
        .unwrap_or("")
        .trim_matches(|c| c == '\0' || c == ' ');
    let brand = if brand.is_empty() { "unknown" } else { brand };
    let (family, model, stepping) = id.family_model_stepping();
    let count = cpus.count_ones();
    let words = [
        (id.edx1, EDX1),
        (id.edx_ext, EDX_EXT),
        (id.ecx1, ECX1),
        (id.ecx_ext, ECX_EXT),
        (id.ebx7, EBX7),
    ];
    for cpu in (0..64).filter(|&c| cpus >> c & 1 != 0) {
        let _ = write!(
            w,
            "processor\t: {cpu}\nvendor_id\t: {vendor}\ncpu family\t: {family}\nmodel\t\t: {model}\nmodel name\t: {brand}\nstepping\t: {stepping}\n"
        );
        if id.mhz != 0 {
            let _ = writeln!(w, "cpu MHz\t\t: {}.000", id.mhz);
        }
        let _ = write!(
            w,
            "physical id\t: 0\nsiblings\t: {count}\ncore id\t\t: {cpu}\ncpu cores\t: {count}\napicid\t\t: {cpu}\ninitial apicid\t: {cpu}\nfpu\t\t: yes\nfpu_exception\t: yes\ncpuid level\t: {}\nwp\t\t: yes\nflags\t\t:",
            id.level
        );
        for (word, names) in words {
            for (_, name) in names.iter().filter(|(bit, _)| word >> bit & 1 != 0) {
                let _ = write!(w, " {name}");
            }
        }
        let clflush = (id.ebx1 >> 8 & 0xff) * 8;
        let _ = write!(
            w,
            "\nclflush size\t: {clflush}\ncache_alignment\t: {clflush}\n"
        );
        if id.sizes != 0 {
            let _ = writeln!(
                w,
                "address sizes\t: {} bits physical, {} bits virtual",
                id.sizes & 0xff,
                id.sizes >> 8 & 0xff
            );
        }
        let _ = w.write_str("power management:\n\n");
    }
}
