//! Flash figures of a firmware ELF, read from its section headers.

use std::path::Path;

/// Sizes of the allocated sections of a 32-bit little-endian ELF file, by name.
fn elf32_alloc_sections(bytes: &[u8]) -> Vec<(String, u32, bool)> {
    let u16_at = |o: usize| u16::from_le_bytes([bytes[o], bytes[o + 1]]) as usize;
    let u32_at = |o: usize| u32::from_le_bytes(bytes[o..o + 4].try_into().unwrap());
    assert_eq!(&bytes[..4], b"\x7fELF", "not an ELF file");
    assert_eq!((bytes[4], bytes[5]), (1, 1), "not ELF32 little-endian");
    let (shoff, shentsize, shnum, shstrndx) = (
        u32_at(0x20) as usize,
        u16_at(0x2E),
        u16_at(0x30),
        u16_at(0x32),
    );
    let sh = |i: usize| shoff + i * shentsize;
    let strtab = u32_at(sh(shstrndx) + 16) as usize;
    (0..shnum)
        .filter_map(|i| {
            let h = sh(i);
            let (name, kind, flags, size) =
                (u32_at(h), u32_at(h + 4), u32_at(h + 8), u32_at(h + 20));
            const SHF_ALLOC: u32 = 2;
            const SHT_NOBITS: u32 = 8;
            (flags & SHF_ALLOC != 0).then(|| {
                let start = strtab + name as usize;
                let end = start + bytes[start..].iter().position(|&b| b == 0).unwrap();
                let name = String::from_utf8_lossy(&bytes[start..end]).into_owned();
                (name, size, kind != SHT_NOBITS)
            })
        })
        .collect()
}

/// Flash figures: (code = .vector_table + .text, .rodata, .data load image, total).
pub fn flash_sizes(elf: &Path) -> (u32, u32, u32, u32) {
    let bytes = std::fs::read(elf).expect("read ELF");
    let (mut code, mut rodata, mut data) = (0, 0, 0);
    for (name, size, in_file) in elf32_alloc_sections(&bytes) {
        match name.as_str() {
            ".vector_table" | ".text" => code += size,
            ".rodata" => rodata += size,
            ".data" => data += size,
            _ if in_file => code += size,
            _ => {}
        }
    }
    (code, rodata, data, code + rodata + data)
}
