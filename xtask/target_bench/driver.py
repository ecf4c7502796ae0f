#!/usr/bin/env python3
"""Target bench driver: runs the firmware-bench image in an emulated Cortex-M4F and
counts the cycles of the calls it marks.

Run by `cargo xtask target-bench` (which builds the image and installs the pinned
`unicorn` and `capstone` packages into a project-local venv); by hand:

    target/target-bench-venv/bin/python xtask/target_bench/driver.py \
        target/thumbv7em-none-eabihf/release/firmware-bench > result.json

With `--safe-state`, the firmware ELF's failure handlers are run to the safe state
(`safe_state_paths`) and the firmware is booted from reset with every peripheral write
recorded and checked (`boot_trace`, `boot_checks`).

Prints one JSON object (see `summarise`). Exit status 0 when the session ran to its end,
1 with a message on stderr otherwise.

How it counts
-------------
Two Unicorn instances (Cortex-M4 model, FPU on) share the image's flash and RAM. `run`
executes the session (the plant, the glue) at full speed with no hooks. When the image
calls `bench_marker(BEGIN_*, tag)`, the registers move to `meas`, which carries a
permanent basic-block hook, runs the measured call up to `bench_marker(END)`, and hands
the registers back. The marker's body never runs: both instances stop at its entry
(`until`), the driver reads r0/r1 and resumes at lr.

Every translated block is disassembled once with Capstone and costed with the Cortex-M4
timings below (ARM DDI 0439, Cortex-M4 Technical Reference Manual, section 3.3.1 and
table 7-1 for the FPU). The hook adds a block's cost each time it runs; a conditional
branch (or conditional PC write) ending a block pays the refill when the next block
is not its fall-through.

Timing table (cycles; P = pipeline refill after a taken branch, taken as 2 of the TRM's
1..3; N = registers transferred):

  data processing (MOV, ADD, shifts, compare, bitfield, extend, CLZ, ...)  1
  MUL, SMULL, UMULL, SMLAL, UMLAL, DSP multiplies                          1
  MLA, MLS                                                                 2
  SDIV, UDIV                                                               12 (the TRM's 2..12: worst case;
                                                                              the early exit depends on data)
  LDR, LDRB/H, LDRSB/H, STR, STRB/H (and VLDR.32/VSTR.32)                 2, or 1 right after another
                                                                              single load/store (pipelined)
  LDRD, STRD, VLDR.64, VSTR.64                                             3 (1+N)
  LDM, STM, PUSH, POP, VLDM, VSTM, VPUSH, VPOP                             1+N (N words)
  LDREX, STREX                                                             2
  B, BL, BX, BLX (taken)                                                   1+P = 3
  conditional B, CBZ, CBNZ                                                 1 not taken, 1+P taken
  TBB, TBH                                                                 2+P = 4
  POP / LDM with PC, LDR PC                                                1+N+P / 2+P
  data processing writing PC                                               1+P
  IT                                                                       1, or 0 when folded onto a
                                                                              preceding 16-bit instruction
  instructions skipped inside an IT block                                  as if executed (an upper bound)
  VADD, VSUB, VMUL, VNMUL, VABS, VNEG, VCMP, VCVT, VMOV, VMRS, VMSR        1
  VMOV of two core registers                                               2
  VMLA, VMLS, VNMLA, VNMLS, VFMA, VFMS, VFNMA, VFNMS                        3
  VDIV.F32, VSQRT.F32                                                      14
  MRS, MSR, CPSID, CPSIE                                                   2
  DMB, DSB, ISB                                                            4
  anything else                                                            1 (listed in `unclassified`)

Software double-precision maths (compiler-builtins' __adddf3, ...) and libm are plain
integer code and costed as such. Flash wait states (the G474's ART accelerator at 170 MHz)
are not modelled: the board's DWT cycle counter is the reference (see the README).

Stack: each block's lowest stack-pointer offset is found statically (PUSH, SUB SP, VPUSH,
STR/STM with SP writeback); at the entry of a block that lowers SP the driver reads SP.
A call's stack is its SP at the begin marker minus the lowest SP seen during it.
"""

from array import array
import ctypes
from importlib.metadata import version
import json
import struct
import sys
import time

import capstone
from capstone import arm_const as A
import unicorn
from unicorn import arm_const as U

# --- Marker protocol (keep in step with firmware/bench/src/image.rs) -----------------
BEGIN_KINDS = {1: "step", 2: "receive", 3: "transmit", 4: "persist_result", 5: "empty"}
END = 0x10
NOTE = 0x11
DONE = 0x20
FAIL = 0x21
PHASES = {1: "locked", 2: "spin_up", 3: "vibrating", 4: "capture", 5: "stopping", 6: "fault",
          7: "stream"}
TYPICAL_PHASES = ("locked", "spin_up", "vibrating", "capture", "stream")
STATES = {0: "locked", 1: "spin_up", 2: "vibrating", 3: "stopping", 4: "fault"}
REQUESTS = {1: "Hello", 2: "StartTelemetry", 3: "Release", 4: "Heartbeat", 5: "StartCapture",
            6: "SetParameters", 7: "StartStream", 8: "StopStream"}
FAILURES = {
    1: "a fault latched (fault bits {detail:#x})",
    2: "the supervisor did not reach Vibrating in time (target {detail} Hz)",
    3: "the supervisor did not reach Locked in time",
    4: "the capture did not finish uploading in time",
    5: "the calibration was not handed out for a flash write ({detail} writes)",
    6: "a request could not be encoded (request kind {detail})",
    7: "the bench image panicked",
    8: "the 10 kHz stream skipped {detail} ADC samples (the link fell behind)",
}

# --- Memory map (memory.x: flash 512 KiB, RAM 96 KiB) --------------------------------
FLASH = (0x0800_0000, 512 * 1024)
RAM = (0x2000_0000, 96 * 1024)
# System control space (cortex-m-rt enables the FPU through CPACR): plain memory here.
SCS = (0xE000_0000, 0x10_0000)

# --- Timing table ---------------------------------------------------------------------
P = 2  # pipeline refill after a taken branch (the TRM's P is 1..3)
DIV_CYCLES = 12
VDIV_CYCLES = 14

WALL_LIMIT_US = 120_000_000  # one emu_start may not run longer than this (a hung image)


def ins_set(*names):
    return {getattr(A, "ARM_INS_" + n) for n in names}


LOAD_STORE_SINGLE = ins_set(
    "LDR", "LDRB", "LDRH", "LDRSB", "LDRSH", "LDRT", "LDRBT", "LDRHT", "LDRSBT", "LDRSHT",
    "STR", "STRB", "STRH", "STRT", "STRBT", "STRHT")
DOUBLE_LOAD_STORE = ins_set("LDRD", "STRD")
EXCLUSIVE = ins_set("LDREX", "LDREXB", "LDREXH", "STREX", "STREXB", "STREXH")
MULTI = ins_set("LDM", "LDMDB", "LDMDA", "LDMIB", "STM", "STMDB", "STMDA", "STMIB", "PUSH", "POP")
VMULTI = ins_set("VLDMIA", "VLDMDB", "VSTMIA", "VSTMDB", "VPUSH", "VPOP")
VSINGLE = ins_set("VLDR", "VSTR")
PUSH_POP = ins_set("PUSH", "POP")
VPUSH_VPOP = ins_set("VPUSH", "VPOP")
BRANCH = ins_set("B", "BL", "BX", "BLX")
CALL = ins_set("BL", "BLX")
COMPARE_BRANCH = ins_set("CBZ", "CBNZ")
TABLE_BRANCH = ins_set("TBB", "TBH")
MUL2 = ins_set("MLA", "MLS")
DIV = ins_set("SDIV", "UDIV")
VFP3 = ins_set("VMLA", "VMLS", "VNMLA", "VNMLS", "VFMA", "VFMS", "VFNMA", "VFNMS")
VFP14 = ins_set("VDIV", "VSQRT")
SYSTEM2 = ins_set("MRS", "MSR", "CPS")
BARRIER = ins_set("DMB", "DSB", "ISB")
ONE_CYCLE = ins_set(
    # data processing
    "ADC", "ADD", "ADDW", "ADR", "AND", "ASR", "BFC", "BFI", "BIC", "CLZ", "CMN", "CMP", "EOR",
    "LSL", "LSR", "MOV", "MOVS", "MOVT", "MOVW", "MVN", "NEG", "ORN", "ORR", "PKHBT", "PKHTB",
    "RBIT", "REV", "REV16", "REVSH", "ROR", "RRX", "RSB", "SBC", "SBFX", "SEL", "SSAT", "SSAT16",
    "SUB", "SUBS", "SUBW", "SXTAB", "SXTAB16", "SXTAH", "SXTB", "SXTB16", "SXTH", "TEQ", "TST",
    "UBFX", "USAT", "USAT16", "UXTAB", "UXTAB16", "UXTAH", "UXTB", "UXTB16", "UXTH", "USAD8",
    "USADA8", "QADD", "QSUB", "QDADD", "QDSUB", "QADD16", "QADD8", "QSUB16", "QSUB8", "QASX",
    "QSAX", "SADD16", "SADD8", "SSUB16", "SSUB8", "SASX", "SSAX", "UADD16", "UADD8", "USUB16",
    "USUB8", "UASX", "USAX", "UQADD16", "UQADD8", "UQSUB16", "UQSUB8", "UQASX", "UQSAX",
    "SHADD16", "SHADD8", "SHSUB16", "SHSUB8", "SHASX", "SHSAX", "UHADD16", "UHADD8", "UHSUB16",
    "UHSUB8", "UHASX", "UHSAX",
    # single-cycle multiplies of the M4
    "MUL", "SMULL", "UMULL", "SMLAL", "UMLAL", "UMAAL", "SMULBB", "SMULBT", "SMULTB", "SMULTT",
    "SMULWB", "SMULWT", "SMLABB", "SMLABT", "SMLATB", "SMLATT", "SMLAWB", "SMLAWT", "SMLAD",
    "SMLADX", "SMLSD", "SMLSDX", "SMLALD", "SMLALDX", "SMLSLD", "SMLSLDX", "SMLALBB", "SMLALBT",
    "SMLALTB", "SMLALTT", "SMMUL", "SMMULR", "SMMLA", "SMMLAR", "SMMLS", "SMMLSR", "SMUAD",
    "SMUADX", "SMUSD", "SMUSDX",
    # FPU, single cycle
    "VADD", "VSUB", "VMUL", "VNMUL", "VABS", "VNEG", "VCMP", "VCMPE", "VCVT", "VCVTR", "VCVTB",
    "VCVTT", "VMRS", "VMSR", "FCONSTS", "FMSTAT", "FADDS", "FSUBS", "FCMPZS",
    # hints
    "NOP", "YIELD", "SEV", "WFE", "WFI", "HINT", "CLREX", "PLD", "PLI", "PLDW")

D_REGS = set(range(A.ARM_REG_D0, A.ARM_REG_D31 + 1))
S_REGS = set(range(A.ARM_REG_S0, A.ARM_REG_S31 + 1))


def reg_list_words(insn, skip_base):
    """Words moved by a register-list instruction (D registers count two)."""
    regs = [op.reg for op in insn.operands if op.type == A.ARM_OP_REG]
    if skip_base:
        regs = regs[1:]
    return sum(2 if r in D_REGS else 1 for r in regs), regs


def is_conditional(insn):
    return insn.cc not in (A.ARM_CC_AL, A.ARM_CC_INVALID)


class Block:
    """A translated block's static cost."""

    __slots__ = ("addr", "cycles", "insns", "cond_fallthrough", "sp_min", "sp_unknown", "call")

    def __init__(self, addr, cycles, insns, cond_fallthrough, sp_min, sp_unknown, call):
        self.addr = addr
        self.cycles = cycles
        self.insns = insns
        # Set when the block ends in a conditional PC write: the fall-through address.
        self.cond_fallthrough = cond_fallthrough
        # Lowest SP offset within the block, relative to its entry (<= 0).
        self.sp_min = sp_min
        # SP written in a way the static scan cannot follow.
        self.sp_unknown = sp_unknown
        # Set when the block ends in BL/BLX: (address of the call, return address).
        self.call = call


class Costing:
    """Disassembles and costs blocks."""

    def __init__(self):
        self.md = capstone.Cs(capstone.CS_ARCH_ARM,
                              capstone.CS_MODE_THUMB | capstone.CS_MODE_MCLASS)
        self.md.detail = True
        self.unclassified = {}

    def insn_cost(self, insn, prev):
        """(cycles, refill_if_taken) of one instruction, `prev` the one before it in the
        block. `refill_if_taken`: a conditional PC write, whose refill P is added only when
        the next block is not the fall-through; unconditional PC writes include P."""
        i = insn.id
        writes_pc = self._writes_pc(insn)
        cond = is_conditional(insn) or i in COMPARE_BRANCH

        def pc_write(base):
            if not writes_pc:
                return base, False
            return (base, True) if cond else (base + P, False)

        prev_single = prev is not None and (
            prev.id in LOAD_STORE_SINGLE or (prev.id in VSINGLE and not self._is_d(prev)))
        if i in LOAD_STORE_SINGLE:
            if writes_pc:
                return pc_write(2)
            return (1 if prev_single else 2), False
        if i in VSINGLE:
            if self._is_d(insn):
                return 3, False
            return (1 if prev_single else 2), False
        if i in DOUBLE_LOAD_STORE:
            return 3, False
        if i in EXCLUSIVE:
            return 2, False
        if i in MULTI:
            words, _ = reg_list_words(insn, skip_base=i not in PUSH_POP)
            return pc_write(1 + words)
        if i in VMULTI:
            words, _ = reg_list_words(insn, skip_base=i not in VPUSH_VPOP)
            return 1 + words, False
        if i in BRANCH or i in COMPARE_BRANCH:
            return pc_write(1)
        if i in TABLE_BRANCH:
            return pc_write(2)
        if i == A.ARM_INS_IT:
            folded = prev is not None and prev.size == 2 and not self._writes_pc(prev)
            return (0 if folded else 1), False
        if i in MUL2:
            return 2, False
        if i in DIV:
            return DIV_CYCLES, False
        if i in VFP3:
            return 3, False
        if i in VFP14:
            return VDIV_CYCLES, False
        if i == A.ARM_INS_VMOV:
            core = [op for op in insn.operands
                    if op.type == A.ARM_OP_REG and op.reg not in D_REGS and op.reg not in S_REGS]
            return (2 if len(core) == 2 else 1), False
        if i in SYSTEM2:
            return 2, False
        if i in BARRIER:
            return 4, False
        if i in ONE_CYCLE:
            return pc_write(1)
        self.unclassified[insn.mnemonic] = self.unclassified.get(insn.mnemonic, 0) + 1
        return pc_write(1)

    @staticmethod
    def _is_d(insn):
        return any(op.type == A.ARM_OP_REG and op.reg in D_REGS for op in insn.operands)

    @staticmethod
    def _writes_pc(insn):
        # Capstone leaves PC out of CBZ/CBNZ's written registers.
        if insn.id in BRANCH or insn.id in COMPARE_BRANCH or insn.id in TABLE_BRANCH:
            return True
        _, written = insn.regs_access()
        return A.ARM_REG_PC in written

    @staticmethod
    def sp_delta(insn):
        """SP change of one instruction: an int, or None when it cannot be followed."""
        i = insn.id
        ops = insn.operands
        # Capstone lists the D registers, not SP, as VPUSH/VPOP's written registers.
        if i in ins_set("PUSH", "VPUSH"):
            return -4 * reg_list_words(insn, skip_base=False)[0]
        if i in ins_set("POP", "VPOP"):
            return 4 * reg_list_words(insn, skip_base=False)[0]
        _, written = insn.regs_access()
        if A.ARM_REG_SP not in written:
            return 0
        if i in ins_set("SUB", "SUBW", "ADD", "ADDW") and len(ops) >= 2:
            dst = ops[0]
            if dst.type == A.ARM_OP_REG and dst.reg == A.ARM_REG_SP:
                imm = ops[-1]
                src_sp = len(ops) == 2 or (ops[1].type == A.ARM_OP_REG
                                           and ops[1].reg == A.ARM_REG_SP)
                if imm.type == A.ARM_OP_IMM and src_sp:
                    return -imm.imm if i in ins_set("SUB", "SUBW") else imm.imm
            return None
        if i in ins_set("STMDB") and ops and ops[0].reg == A.ARM_REG_SP:
            return -4 * reg_list_words(insn, skip_base=True)[0]
        if i in ins_set("LDM") and ops and ops[0].reg == A.ARM_REG_SP:
            return 4 * reg_list_words(insn, skip_base=True)[0]
        if i in ins_set("VSTMDB") and ops and ops[0].reg == A.ARM_REG_SP:
            return -4 * reg_list_words(insn, skip_base=True)[0]
        if i in ins_set("VLDMIA") and ops and ops[0].reg == A.ARM_REG_SP:
            return 4 * reg_list_words(insn, skip_base=True)[0]
        if insn.writeback and len(ops) >= 2 and ops[-1].type == A.ARM_OP_MEM \
                and ops[-1].mem.base == A.ARM_REG_SP:
            return ops[-1].mem.disp  # pre-indexed, e.g. str r0, [sp, #-8]!
        if insn.writeback and len(ops) >= 3 and ops[1].type == A.ARM_OP_MEM \
                and ops[1].mem.base == A.ARM_REG_SP and ops[2].type == A.ARM_OP_IMM:
            return ops[2].imm  # post-indexed, e.g. ldr r0, [sp], #8
        return None

    def block(self, code, addr):
        cycles = insns = 0
        prev = None
        cond_fallthrough = None
        sp = sp_min = 0
        sp_unknown = False
        call = None
        for insn in self.md.disasm(code, addr):
            c, refill_if_taken = self.insn_cost(insn, prev)
            cycles += c
            insns += 1
            d = self.sp_delta(insn)
            if d is None:
                sp_unknown = True
            else:
                sp += d
                sp_min = min(sp_min, sp)
            # Only the block's last instruction can leave it; a conditional PC write
            # earlier (inside an IT block that the translator did not split) falls through.
            cond_fallthrough = insn.address + insn.size if refill_if_taken else None
            call = ((insn.address, insn.address + insn.size) if insn.id in CALL else None)
            prev = insn
        return Block(addr, cycles, insns, cond_fallthrough, sp_min, sp_unknown, call)


# Known sequences and their cost under the table above: checked before every run, so a
# Capstone that decodes differently fails loudly instead of counting wrong.
# (hex, cycles, lowest SP offset, ends in a conditional branch)
SELF_TEST = [
    ("f0b5", 6, -20, False),                   # push {r4-r7, lr}: 1+N
    ("0868 4a68 1a60", 4, 0, False),           # ldr; ldr; str: 2, then pipelined 1, 1
    ("4843", 1, 0, False),                     # muls
    ("b0fb f1f0", 12, 0, False),               # udiv: worst case
    ("80ee 200a", 14, 0, False),               # vdiv.f32
    ("b1ee e00a", 14, 0, False),               # vsqrt.f32
    ("20ee 200a 30ee 200a", 2, 0, False),      # vmul.f32; vadd.f32
    ("90ed 000a", 2, 0, False),                # vldr s0
    ("90ed 000b", 3, 0, False),                # vldr d0
    ("f0bd", 8, 0, False),                     # pop {r4-r7, pc}: 1+N+P
    ("00d1", 1, 0, True),                      # bne: 1, +P when taken
    ("0028 08bf 0120", 2, 0, False),           # cmp; it eq (folded); moveq
    ("00f0 00f8", 3, 0, False),                # bl: 1+P
    ("2ded 108b", 17, -64, False),             # vpush {d8-d15}: 1+16
    ("84b0", 1, -16, False),                   # sub sp, #16
    ("4df8 080d", 2, -8, False),               # str r0, [sp, #-8]!
    ("51ec 100b", 2, 0, False),                # vmov r0, r1, d0
    ("08b1", 1, 0, True),                      # cbz: 1, +P when taken
]


def self_test():
    """Costs SELF_TEST with a fresh Costing; returns the mismatches."""
    costing = Costing()
    errors = []
    for text, cycles, sp_min, cond in SELF_TEST:
        b = costing.block(bytes.fromhex(text.replace(" ", "")), 0x1000)
        got = (b.cycles, b.sp_min, b.cond_fallthrough is not None)
        want = (cycles, sp_min, cond)
        if got != want:
            errors.append(f"{text}: costed {got}, expected {want}")
    return errors


# --- ELF ------------------------------------------------------------------------------
def read_elf(path):
    """Loadable segments, symbols and the initial vector table of a 32-bit ARM ELF."""
    with open(path, "rb") as f:
        elf = f.read()
    if elf[:4] != b"\x7fELF" or elf[4] != 1 or elf[5] != 1:
        raise ValueError(f"{path} is not a 32-bit little-endian ELF")
    (_, _, machine, _, _, phoff, shoff, _, _, phentsize, phnum, shentsize, shnum,
     _) = struct.unpack_from("<16sHHIIIIIHHHHHH", elf, 0)
    if machine != 40:
        raise ValueError(f"{path} is not an ARM ELF (e_machine {machine})")
    segments = []
    for k in range(phnum):
        p_type, off, vaddr, paddr, filesz, memsz, _, _ = struct.unpack_from(
            "<8I", elf, phoff + k * phentsize)
        if p_type == 1:  # PT_LOAD
            segments.append((paddr, elf[off:off + filesz]))
    sections = [struct.unpack_from("<10I", elf, shoff + k * shentsize) for k in range(shnum)]
    symbols = {}
    for sh in sections:
        if sh[1] != 2:  # SHT_SYMTAB
            continue
        strtab = sections[sh[6]]
        for j in range(sh[5] // 16):
            name_off, value, size, info, _, _ = struct.unpack_from("<IIIBBH", elf, sh[4] + j * 16)
            start = strtab[4] + name_off
            name = elf[start:elf.index(b"\0", start)].decode("utf-8", "replace")
            if name:
                symbols[name] = (value, size, info & 0xF)
    return segments, symbols


class Failure(Exception):
    """The session could not be measured; the message says why."""


class Driver:
    """The two emulator instances and the measurement state."""

    GPR = [U.UC_ARM_REG_R0 + k for k in range(13)] + [
        U.UC_ARM_REG_SP, U.UC_ARM_REG_LR, U.UC_ARM_REG_XPSR, U.UC_ARM_REG_FPSCR] + [
        U.UC_ARM_REG_D0 + k for k in range(16)]

    def __init__(self, elf_path):
        segments, self.symbols = read_elf(elf_path)
        if "bench_marker" not in self.symbols:
            raise Failure(f"{elf_path} has no `bench_marker` symbol: not a target-bench image")
        self.marker = self.symbols["bench_marker"][0] & ~1
        self.buffers = [ctypes.create_string_buffer(size) for _, size in (FLASH, RAM, SCS)]
        self.run = self._instance()
        self.meas = self._instance()
        for addr, data in segments:
            self.run.mem_write(addr, data)
        vector = bytes(self.run.mem_read(FLASH[0], 8))
        self.initial_sp, reset = struct.unpack("<II", vector)
        self.run.reg_write(U.UC_ARM_REG_SP, self.initial_sp)
        self.pc = reset & ~1
        self.costing = Costing()
        self.blocks = {}
        self.meas.hook_add(unicorn.UC_HOOK_BLOCK, self._on_block)
        self._reset_call()

    def _instance(self):
        uc = unicorn.Uc(unicorn.UC_ARCH_ARM, unicorn.UC_MODE_THUMB | unicorn.UC_MODE_MCLASS)
        uc.ctl_set_cpu_model(U.UC_CPU_ARM_CORTEX_M4)
        for (base, size), buf in zip((FLASH, RAM, SCS), self.buffers):
            uc.mem_map_ptr(base, size, unicorn.UC_PROT_ALL, ctypes.addressof(buf))
        return uc

    def _reset_call(self):
        self.cycles = 0
        self.insns = 0
        self.pending = None
        self.profile = {}
        # Calls in flight: (return address, call address, cycles at the callee's entry).
        self.stack = []
        self.call_pending = None
        # Cycles spent inside the calls made at each call address (callees included).
        self.calls = {}
        self.sp_low = None
        self.sp_check_next = False

    def _block(self, addr, size):
        key = (addr, size)
        b = self.blocks.get(key)
        if b is None:
            code = bytes(self.meas.mem_read(addr, size))
            b = self.costing.block(code, addr)
            self.blocks[key] = b
        return b

    def _on_block(self, uc, addr, size, _user):
        if addr == self.marker or size == 0:
            return
        pending = self.pending
        if pending is not None:
            # The previous block ended in a conditional PC write.
            fall, prev_addr = pending
            if addr != fall:
                self.cycles += P
                self.profile[prev_addr][0] += P
            self.pending = None
        stack = self.stack
        if self.call_pending is not None:
            ret, at = self.call_pending
            stack.append((ret, at, self.cycles))
            self.call_pending = None
        elif stack and addr == stack[-1][0]:
            self._returned()
        elif stack and any(addr == f[0] for f in stack):
            # Returned past frames that never returned themselves (tail calls).
            while addr != stack[-1][0]:
                self._returned()
            self._returned()
        b = self._block(addr, size)
        self.cycles += b.cycles
        self.insns += b.insns
        entry = self.profile.get(addr)
        if entry is None:
            self.profile[addr] = [b.cycles, b.insns]
        else:
            entry[0] += b.cycles
            entry[1] += b.insns
        if b.cond_fallthrough is not None:
            self.pending = (b.cond_fallthrough, addr)
        if b.call is not None:
            self.call_pending = (b.call[1], b.call[0])
        if b.sp_min < 0 or self.sp_check_next:
            sp = uc.reg_read(U.UC_ARM_REG_SP)
            low = sp + b.sp_min
            if self.sp_low is None or low < self.sp_low:
                self.sp_low = low
        self.sp_check_next = b.sp_unknown

    def _returned(self):
        _, at, start = self.stack.pop()
        self.calls[at] = self.calls.get(at, 0) + self.cycles - start

    def _run_to_marker(self, uc, pc):
        try:
            uc.emu_start(pc | 1, self.marker, timeout=WALL_LIMIT_US)
        except unicorn.UcError as e:
            at = uc.reg_read(U.UC_ARM_REG_PC)
            raise Failure(f"the emulator stopped at {at:#010x} ({self.symbol_at(at)}): {e}")
        at = uc.reg_read(U.UC_ARM_REG_PC)
        if at != self.marker:
            raise Failure(f"no marker within {WALL_LIMIT_US // 1_000_000} s; the image is at "
                          f"{at:#010x} ({self.symbol_at(at)})")
        r0, r1, lr = uc.reg_read_batch([U.UC_ARM_REG_R0, U.UC_ARM_REG_R1, U.UC_ARM_REG_LR])
        return r0, r1, lr & ~1

    def symbol_at(self, addr):
        best = None
        for name, (value, size, kind) in self.symbols.items():
            start = value & ~1
            if kind == 2 and start <= addr < start + max(size, 1):
                best = name
        return best or "unknown"

    def _transfer(self, src, dst):
        dst.reg_write_batch(list(zip(self.GPR, src.reg_read_batch(self.GPR))))

    def measure(self, pc):
        """Runs one marked call in `meas` from `pc`; returns (cycles, insns, stack, profile, lr)."""
        self._transfer(self.run, self.meas)
        sp0 = self.meas.reg_read(U.UC_ARM_REG_SP)
        self._reset_call()
        code, _, lr = self._run_to_marker(self.meas, pc)
        if code != END:
            raise Failure(f"marker {code:#x} inside a measured call (expected END)")
        self._transfer(self.meas, self.run)
        while self.stack:
            self._returned()
        stack = sp0 - min(self.sp_low if self.sp_low is not None else sp0, sp0)
        return self.cycles, self.insns, stack, pack(self.profile, self.calls), lr, sp0

    def session(self):
        """Runs the image to its end; returns the calls and their profiles."""
        calls = []
        worst = {}
        overhead = None
        lowest_sp = self.initial_sp
        pc = self.pc
        while True:
            code, arg, lr = self._run_to_marker(self.run, pc)
            pc = lr
            if code in BEGIN_KINDS:
                cycles, insns, stack, profile, pc, sp0 = self.measure(pc)
                lowest_sp = min(lowest_sp, sp0 - stack)
                kind = BEGIN_KINDS[code]
                if kind == "empty":
                    overhead = (cycles, insns)
                    continue
                if overhead is None:
                    raise Failure("the image measured a call before the empty measurement")
                call = {
                    "kind": kind, "tag": arg,
                    "cycles": cycles - overhead[0], "instructions": insns - overhead[1],
                    "stack": stack, "note": None, "profile": profile,
                }
                if kind != "step":
                    # Only the worst call of each kind is profiled: keep no other profile.
                    best = worst.get(kind)
                    if best is None or call["cycles"] > best["cycles"]:
                        if best is not None:
                            best["profile"] = None
                        worst[kind] = call
                    else:
                        call["profile"] = None
                calls.append(call)
            elif code == NOTE:
                if calls:
                    calls[-1]["note"] = arg
            elif code == DONE:
                return calls, overhead, self.initial_sp - lowest_sp
            elif code == FAIL:
                reason, detail = arg & 0xFF, arg >> 8
                text = FAILURES.get(reason, "unknown failure {reason}").format(
                    detail=detail, reason=reason)
                raise Failure(f"the bench session failed: {text}")
            else:
                raise Failure(f"unknown marker code {code:#x}")


def median(values):
    s = sorted(values)
    return s[len(s) // 2] if s else None


def describe(call):
    """A call's readable details (phase, frequency, request, boundary)."""
    kind, tag, note = call["kind"], call["tag"], call["note"] or 0
    d = {"kind": kind}
    if kind == "step":
        d["phase"] = PHASES.get(tag & 0xFF, "unknown")
        d["target_hz"] = tag >> 8
        d["revolution_boundary"] = bool(note & 1)
        d["state_after"] = STATES.get((note >> 8) & 0xFF, "unknown")
    elif kind == "receive":
        d["request"] = REQUESTS.get(tag & 0xFF, "unknown")
        d["frame_complete"] = bool(tag >> 8)
    elif kind == "transmit":
        d["bytes"] = note & 0xFFFF
        d["capture_uploading"] = bool((note >> 16) & 1)
        d["streaming"] = bool((note >> 17) & 1)
    return d


def pack(blocks, calls):
    """A call's profile in flat arrays (thousands of calls are kept until the end)."""
    b = array("q")
    for a, (c, n) in blocks.items():
        b.extend((a, c, n))
    k = array("q")
    for a, c in calls.items():
        k.extend((a, c))
    return b, k


def profile_blocks(profile):
    """[[address, cycles, instructions], ...], most cycles first."""
    b = profile[0]
    rows = [[b[j], b[j + 1], b[j + 2]] for j in range(0, len(b), 3)]
    return sorted(rows, key=lambda r: -r[1])


def profile_calls(profile):
    """[[call address, cycles inside the calls made there], ...], most cycles first."""
    k = profile[1]
    return sorted(([k[j], k[j + 1]] for j in range(0, len(k), 2)), key=lambda r: -r[1])


def summarise(calls, overhead, image_stack, costing, elapsed):
    steps = [c for c in calls if c["kind"] == "step"]
    typical = [c for c in steps if describe(c)["phase"] in TYPICAL_PHASES]
    locks = [c for c in calls if c["kind"] != "step"]
    if not typical:
        raise Failure("the session measured no step in the typical phases")
    by_cycles = sorted(typical, key=lambda c: c["cycles"])
    median_call = by_cycles[len(by_cycles) // 2]
    worst_step = max(steps, key=lambda c: c["cycles"])
    worst_lock = max(locks, key=lambda c: c["cycles"]) if locks else None

    groups = {}
    for c in calls:
        d = describe(c)
        if c["kind"] == "step":
            key = ("step", d["phase"], d["target_hz"] if d["phase"] not in ("locked",) else 0,
                   d["revolution_boundary"])
        elif c["kind"] == "receive":
            key = ("receive", d["request"], 0, False)
        elif c["kind"] == "transmit":
            key = ("transmit", "capture upload" if d["capture_uploading"] else
                   ("idle" if d["bytes"] == 0 else
                    ("stream" if d["streaming"] else "frames")), 0, False)
        else:
            key = (c["kind"], "", 0, False)
        groups.setdefault(key, []).append(c)
    rows = []
    for (kind, what, hz, boundary), cs in sorted(groups.items(), key=lambda kv: kv[0]):
        cyc = [c["cycles"] for c in cs]
        rows.append({
            "kind": kind, "what": what, "target_hz": hz, "revolution_boundary": boundary,
            "calls": len(cs), "cycles_median": median(cyc), "cycles_max": max(cyc),
            "instructions_median": median([c["instructions"] for c in cs]),
            "stack_max": max(c["stack"] for c in cs),
        })

    def picked(name, call):
        return {"name": name, "call": dict(describe(call), cycles=call["cycles"],
                                           instructions=call["instructions"],
                                           stack=call["stack"]),
                "blocks": profile_blocks(call["profile"]),
                "calls": profile_calls(call["profile"])}

    profiles = [picked("typical step (median)", median_call),
                picked("worst step", worst_step)]
    for kind in ("receive", "transmit", "persist_result"):
        of_kind = [c for c in locks if c["kind"] == kind]
        if of_kind:
            profiles.append(picked(f"worst {kind}", max(of_kind, key=lambda c: c["cycles"])))
    return {
        "step_cycles_typical": median_call["cycles"],
        "step_cycles_worst": worst_step["cycles"],
        "lock_cycles_worst": worst_lock["cycles"] if worst_lock else 0,
        "stack_bytes_worst": max(c["stack"] for c in calls),
        "image_stack_bytes": image_stack,
        "typical_steps": len(typical),
        "steps": len(steps),
        "lock_calls": len(locks),
        "marker_overhead": {"cycles": overhead[0], "instructions": overhead[1]},
        "worst_step": describe(worst_step),
        "worst_lock": describe(worst_lock) if worst_lock else None,
        "groups": rows,
        "profiles": profiles,
        "unclassified": costing.unclassified,
        "model": {"P": P, "div": DIV_CYCLES, "vdiv_vsqrt": VDIV_CYCLES},
        "emulator": {"unicorn": version("unicorn"), "capstone": version("capstone"),
                     "cpu": "cortex-m4"},
        "elapsed_s": round(elapsed, 1),
    }


# --- Panic to safe state (the firmware ELF itself) ----------------------------------
TIM1_BDTR = 0x4001_2C44
BDTR_MOE = 1 << 15
EXCEPTION_ENTRY = 12  # cycles from an exception to its handler's first instruction (TRM 3.3)
SAFE_STATE_LIMIT = 170_000  # budget: 1 ms at 170 MHz
# (name in the result, symbol, entered as an exception)
SAFE_STATE_PATHS = [
    ("panic", "rust_begin_unwind", False),
    ("hard_fault", "HardFault", True),
    ("unhandled_interrupt", "DefaultHandler", True),
    ("control_stall", "WWDG", True),
]


def safe_state_paths(elf_path, enable_bsrr, enable_bit):
    """Runs each failure handler of the real firmware from its entry, peripherals as plain
    memory (pages mapped on first touch), until both writes of the safe state happened:
    TIM1_BDTR written with MOE clear (it reads as set before) and the bridge enable's
    GPIO BSRR written with its reset bit. Returns {path: {cycles, instructions, ...}}."""
    segments, symbols = read_elf(elf_path)

    def find(name):
        for sym, (value, _, kind) in symbols.items():
            if kind == 2 and (sym == name or sym.endswith(name)):
                return value & ~1
        raise Failure(f"{elf_path} has no `{name}` symbol: not the rig firmware?")

    costing = Costing()
    results = {}
    for label, symbol, exception in SAFE_STATE_PATHS:
        entry = find(symbol)
        uc = unicorn.Uc(unicorn.UC_ARCH_ARM, unicorn.UC_MODE_THUMB | unicorn.UC_MODE_MCLASS)
        uc.ctl_set_cpu_model(U.UC_CPU_ARM_CORTEX_M4)
        for base, size in (FLASH, RAM, SCS):
            uc.mem_map(base, size)
        for addr, data in segments:
            uc.mem_write(addr, data)

        def map_page(uc, _access, address, _size, _value, _user):
            uc.mem_map(address & ~0xFFF, 0x1000)
            return True

        uc.hook_add(unicorn.UC_HOOK_MEM_UNMAPPED, map_page)
        # Peripherals as the running firmware left them: MOE set.
        uc.mem_map(TIM1_BDTR & ~0xFFF, 0x1000)
        uc.mem_write(TIM1_BDTR, struct.pack("<I", BDTR_MOE))
        initial_sp = struct.unpack("<I", bytes(uc.mem_read(FLASH[0], 4)))[0]
        # A PanicInfo (and anything it points to) that points at itself, all zero lengths
        # aside: the handler must reach the safe state before it reads any of it.
        fake = RAM[0] + RAM[1] - 0x4000
        uc.mem_write(fake, struct.pack("<16I", *([fake] * 16)))
        uc.reg_write(U.UC_ARM_REG_SP, initial_sp)
        uc.reg_write(U.UC_ARM_REG_R0, fake)
        uc.reg_write(U.UC_ARM_REG_LR, 0xFFFF_FFF9 if exception else 0)
        state = {"cycles": EXCEPTION_ENTRY if exception else 0, "insns": 0, "pending": None,
                 "moe_at": None, "enable_at": None, "writes": []}

        def on_block(uc, addr, size, _user):
            if state["pending"] is not None:
                fall, _ = state["pending"]
                if addr != fall:
                    state["cycles"] += P
                state["pending"] = None
            b = costing.block(bytes(uc.mem_read(addr, size)), addr)
            state["cycles"] += b.cycles
            state["insns"] += b.insns
            if b.cond_fallthrough is not None:
                state["pending"] = (b.cond_fallthrough, addr)
            if state["insns"] > 1_000_000:
                uc.emu_stop()

        def on_write(uc, _access, address, size, value, _user):
            if address >= 0x4000_0000:
                state["writes"].append((address, value & 0xFFFF_FFFF))
            if address == TIM1_BDTR and not value & BDTR_MOE and state["moe_at"] is None:
                state["moe_at"] = state["cycles"]
            if address == enable_bsrr and value >> enable_bit & 1 and state["enable_at"] is None:
                state["enable_at"] = state["cycles"]
            if state["moe_at"] is not None and state["enable_at"] is not None:
                uc.emu_stop()

        uc.hook_add(unicorn.UC_HOOK_BLOCK, on_block)
        uc.hook_add(unicorn.UC_HOOK_MEM_WRITE, on_write)
        try:
            uc.emu_start(entry | 1, 0, timeout=10_000_000, count=2_000_000)
        except unicorn.UcError as e:
            at = uc.reg_read(U.UC_ARM_REG_PC)
            raise Failure(f"the {label} path stopped at {at:#010x} before the safe state: {e}")
        done = state["moe_at"] is not None and state["enable_at"] is not None
        if not done:
            missing = [w for w, k in (("TIM1 BDTR.MOE clear", "moe_at"),
                                      (f"bridge enable low (BSRR {enable_bsrr:#010x} bit "
                                       f"{enable_bit})", "enable_at")) if state[k] is None]
            seen = ", ".join(f"{a:#010x}={v:#x}" for a, v in state["writes"][:8]) or "none"
            raise Failure(f"the firmware's {label} path ({symbol}) never wrote "
                          f"{' and '.join(missing)}; peripheral writes seen: {seen}")
        results[label] = {"symbol": symbol, "cycles": state["cycles"],
                          "instructions": state["insns"],
                          "moe_clear_at": state["moe_at"], "enable_low_at": state["enable_at"],
                          "exception_entry": EXCEPTION_ENTRY if exception else 0}
    return results


# --- Boot trace (the firmware ELF itself, from reset) ----------------------------------
# Peripherals are plain memory (pages mapped on first touch); a read hook gives the status
# bits the init code waits on the values the hardware would show once ready.
RCC_BASE = 0x4002_1000
FLASH_ACR = 0x4002_2000
FLASH_OPTR = 0x4002_2020
PWR_CR5 = 0x4000_7080
RCC_CFGR = RCC_BASE + 0x08
TIM1_BASE = 0x4001_2C00
SYSCFG_CFGR2 = 0x4001_001C
# RCC_APB2RSTR: bit 0 SYSCFGRST (embassy's init pulses it, which clears SYSCFG_CFGR2.CLL).
RCC_APB2RSTR = 0x4002_1040
# GPIOA_OSPEEDR: PA8's speed in bits 16..17 (00 low).
GPIOA_OSPEEDR = 0x4800_0008
NVIC_IPR = 0xE000_E400
# DBGMCU_APB2FZR (RM0440 46.16.4): bit 11 DBG_TIM1_STOP.
DBGMCU_APB2FZR = 0xE004_2010
# The review's margin between the lowest stack pointer at boot and the stack guard, bytes.
STACK_MARGIN_MIN = 2048
COMP3_CSR = 0x4001_0208
ADC1_CFGR = 0x5000_000C
GPIOB_PUPDR = 0x4800_040C
GPIOC_PUPDR = 0x4800_080C
MPU_CTRL, MPU_RBAR, MPU_RASR = 0xE000_ED94, 0xE000_ED9C, 0xE000_EDA0
VREFINT_CAL = 0x1FFF_75AA
STORAGE = (0x0807_C000, 0x4000)
BOOT_INSN_LIMIT = 5_000_000
SYSCLK_HZ = 170_000_000
EXECUTOR_IDLE = "embassy_executor8platform6thread8Executor3run"
FAILURE_SYMBOLS = ("rust_begin_unwind", "HardFault", "DefaultHandler", "NonMaskableInt",
                   "rig_safe_state")


def _ready_bits(uc, address):
    """Before a read: the bits of the status registers the init code polls, as ready."""
    a = address & ~3

    def rd():
        return struct.unpack("<I", bytes(uc.mem_read(a, 4)))[0]

    def wr(v):
        uc.mem_write(a, struct.pack("<I", v & 0xFFFF_FFFF))

    if a == RCC_BASE:  # CR: HSIRDY, HSERDY, PLLRDY follow their ON bits
        v = rd()
        for on, rdy in ((8, 10), (16, 17), (24, 25)):
            v = v | (1 << rdy) if v >> on & 1 else v & ~(1 << rdy)
        wr(v)
    elif a == RCC_CFGR:  # SWS = SW
        v = rd()
        wr((v & ~0xC) | ((v & 3) << 2))
    elif a in (RCC_BASE + 0x90, RCC_BASE + 0x94, RCC_BASE + 0x98):  # LSE, LSI, HSI48 ready
        v = rd()
        wr(v | 2 if v & 1 else v)
    elif 0x5000_0000 <= a < 0x5000_0400 and a & 0xFF == 0x08:  # ADCx_CR
        v = rd() & ~(1 << 31)  # calibration done
        if v & 1:  # ADEN: ADRDY
            isr = a - 8
            uc.mem_write(isr, struct.pack("<I", struct.unpack(
                "<I", bytes(uc.mem_read(isr, 4)))[0] | 1))
        if v & 2:  # ADDIS
            v &= ~3
        wr(v)
    elif 0x4000_4400 <= a < 0x4000_5400 and a & 0xFF == 0x1C:  # USART ISR: TEACK, REACK, TXE, TC
        wr(rd() | (1 << 21) | (1 << 22) | (1 << 7) | (1 << 6))
    elif a == FLASH_OPTR:  # DBANK: the G474RE's factory option byte
        wr(rd() | (1 << 22))
    elif a == TIM1_BASE + 0x10:  # SR: an update has happened (the sampling-phase check)
        wr(rd() | 1)


def stack_guard_top(final):
    """The end (exclusive) of the MPU's stack-guard region from the final MPU writes."""
    rbar, rasr = final.get(MPU_RBAR, 0), final.get(MPU_RASR, 0)
    return (rbar & ~0x1F) + (1 << ((rasr >> 1 & 0x1F) + 1))


def boot_checks(writes, symbols, final, enable_bsrr, enable_bit, lowest_stack=None):
    """The register sequences that matter, from the boot's peripheral writes
    [(instruction, address, value)] and the final values {address: value}. Each check:
    {name, pass, detail, gate} (gate false: a known gap, reported, not failing --check)."""
    checks = []

    def add(name, ok, detail, gate=True):
        checks.append({"name": name, "pass": bool(ok), "detail": detail, "gate": gate})

    def first(pred):
        return next((k for k, (_, a, v) in enumerate(writes) if pred(a, v)), None)

    switch = first(lambda a, v: a == RCC_CFGR and v & 3 == 3)
    boost = first(lambda a, v: a == PWR_CR5 and not v >> 8 & 1)
    latency = first(lambda a, v: a == FLASH_ACR and v & 0xF == 4)
    add("clock: range-1 boost before the switch to the PLL",
        switch is not None and boost is not None and boost < switch,
        "PWR_CR5.R1MODE cleared before RCC_CFGR.SW = PLL")
    add("clock: 4 flash wait states before the switch to the PLL",
        switch is not None and latency is not None and latency < switch,
        "FLASH_ACR.LATENCY = 4 before RCC_CFGR.SW = PLL")
    div2_at_switch = switch is not None and writes[switch][2] >> 4 & 0xF == 0b1000
    div1 = None if switch is None else next(
        (k for k in range(switch + 1, len(writes))
         if writes[k][1] == RCC_CFGR and writes[k][2] >> 4 & 0xF == 0), None)
    add("clock: AHB /2 across the switch, /1 at least 1 us later",
        div2_at_switch and div1 is not None
        and writes[div1][0] - writes[switch][0] >= SYSCLK_HZ // 1_000_000,
        "RM0440 6.1.5/7.2.7: the write with SW = PLL keeps HPRE = /2, HPRE = /1 comes "
        "at least 1 us of SYSCLK cycles later (patches/README.md: embassy-stm32 0.6.0 "
        "patched)")
    arr = final.get(TIM1_BASE + 0x2C)
    cr1 = final.get(TIM1_BASE + 0x00, 0)
    add("TIM1: centre-aligned, ARR 4250 (period 2 ARR: 20 kHz at 170 MHz)",
        arr == 4250 and cr1 >> 5 & 3 == 0b10, f"ARR {arr}, CR1 {cr1:#x}")
    bdtr_writes = [(k, v) for k, (_, a, v) in enumerate(writes) if a == TIM1_BASE + 0x44]
    locked = [k for k, v in bdtr_writes if v >> 8 & 3 == 2 and v >> 12 & 1 and v >> 13 & 1
              and not v >> 14 & 1 and v >> 10 & 1]
    moe_set = [k for k, v in bdtr_writes if v >> 15 & 1]
    add("TIM1: BDTR break on (active high), OSSI, no AOE, LOCK level 2; MOE never set",
        bool(locked) and not moe_set, f"{len(bdtr_writes)} BDTR writes")
    af1 = final.get(TIM1_BASE + 0x60, 0)
    add("TIM1: break from COMP3 only (AF1.BKCMP3E, not inverted, BKINE off)",
        af1 >> 3 & 1 and not af1 & 1 and not af1 >> 12 & 1, f"AF1 {af1:#x}")
    comp = final.get(COMP3_CSR, 0)
    add("COMP3: on, PA0 against DAC3_CH1 (INMSEL 100)",
        comp & 1 and (comp >> 4) & 7 == 0b100 and not comp >> 8 & 1, f"CSR {comp:#x}")
    cfgr = final.get(ADC1_CFGR, 0)
    add("ADC1: triggered by TIM1_TRGO on the rising edge (EXTSEL 9, EXTEN 01)",
        cfgr >> 5 & 0x1F == 9 and cfgr >> 10 & 3 == 1, f"CFGR {cfgr:#x}")
    pulls = [(GPIOB_PUPDR, (6, 7)), (GPIOC_PUPDR, (6, 7))]
    add("encoder inputs PB6/PB7, PC6/PC7 without pulls",
        all(final.get(reg, 0) >> (2 * pin) & 3 == 0 for reg, pins in pulls for pin in pins),
        ", ".join(f"{reg:#x}={final.get(reg, 0):#x}" for reg, _ in pulls))
    add("SYSCFG_CFGR2.CLL: a lockup breaks TIM1", final.get(SYSCFG_CFGR2, 0) & 1,
        f"CFGR2 {final.get(SYSCFG_CFGR2, 0):#x}")
    resets = [k for k, (_, a, v) in enumerate(writes) if a == RCC_APB2RSTR and v & 1]
    cll_sets = [k for k, (_, a, v) in enumerate(writes) if a == SYSCFG_CFGR2 and v & 1]
    add("SYSCFG_CFGR2.CLL set after init's SYSCFG reset pulse",
        bool(cll_sets) and (not resets or cll_sets[-1] > resets[-1]),
        f"last SYSCFGRST write #{resets[-1] if resets else None}, "
        f"last CLL write #{cll_sets[-1] if cll_sets else None}")
    ospeed = final.get(GPIOA_OSPEEDR, 0) >> 16 & 3
    add("PA8 (the 20 kHz PWM) at low speed (GPIOA_OSPEEDR8 = 00)", ospeed == 0,
        f"OSPEEDR8 {ospeed:#b}")
    sheap = symbols.get("__sheap", (0, 0, 0))[0]
    rbar, rasr = final.get(MPU_RBAR, 0), final.get(MPU_RASR, 0)
    size = 1 << ((rasr >> 1 & 0x1F) + 1)
    base = rbar & ~0x1F
    add("stack guard: an MPU region with no access right above the statics",
        final.get(MPU_CTRL, 0) & 1 and rasr & 1 and rasr >> 24 & 7 == 0
        and sheap <= base < sheap + size, f"base {base:#x} size {size} statics end {sheap:#x}")
    margin = None if lowest_stack is None else lowest_stack - (base + size)
    add(f"stack: at least {STACK_MARGIN_MIN} B between the lowest stack pointer at boot "
        "and the guard", margin is not None and margin >= STACK_MARGIN_MIN,
        f"lowest stack access {lowest_stack if lowest_stack is None else hex(lowest_stack)}, "
        f"guard top {base + size:#x}, margin {margin} B")
    # NVIC_IPR: one byte per IRQ (G474: TIM1_BRK_TIM15 24, UART4 52, the control executor).
    ipr = lambda irq: final.get(NVIC_IPR + irq)
    brk, ctl = ipr(24), ipr(52)
    add("trip interrupt above the core lock's ceiling (TIM1_BRK P0, UART4 executor P6 = "
        "BASEPRI ceiling)", brk is not None and ctl == 0x60 and brk < ctl,
        f"TIM1_BRK IPR {brk}, UART4 IPR {ctl}")
    fz = final.get(DBGMCU_APB2FZR)
    add("debug halt: TIM1 not stopped (DBGMCU_APB2FZR.DBG_TIM1_STOP clear): a halt never "
        "brakes the motor", fz is not None and not fz >> 11 & 1,
        f"APB2FZR {fz if fz is None else hex(fz)}")
    enable_low = first(lambda a, v: a == enable_bsrr and v >> enable_bit & 1)
    pwm_af = first(lambda a, v: a == 0x4800_0000 and v >> 16 & 3 == 2)
    add("bridge enable driven low before PA8 becomes TIM1's output",
        enable_low is not None and pwm_af is not None and enable_low < pwm_af,
        "GPIOA_BSRR reset bit before GPIOA_MODER8 = AF")
    return checks


def boot_trace(elf_path, enable_bsrr, enable_bit):
    """Runs the firmware ELF from its reset vector until the thread executor idles, every
    peripheral write recorded; returns {cycles, instructions, reached_executor, checks,
    writes}."""
    segments, symbols = read_elf(elf_path)
    uc = unicorn.Uc(unicorn.UC_ARCH_ARM, unicorn.UC_MODE_THUMB | unicorn.UC_MODE_MCLASS)
    uc.ctl_set_cpu_model(U.UC_CPU_ARM_CORTEX_M4)
    for base, size in (FLASH, RAM, SCS):
        uc.mem_map(base, size)
    uc.mem_write(STORAGE[0], b"\xff" * STORAGE[1])  # an erased calibration store
    for addr, data in segments:
        uc.mem_write(addr, data)
    uc.mem_map(VREFINT_CAL & ~0xFFFF, 0x1_0000)
    uc.mem_write(VREFINT_CAL, struct.pack("<H", 1654))

    def map_page(uc, _access, address, _size, _value, _user):
        uc.mem_map(address & ~0xFFF, 0x1000)
        return True

    by_start = sorted(((v & ~1, v + max(sz, 1), n) for n, (v, sz, k) in symbols.items()
                       if k == 2))
    failure = {v & ~1 for n, (v, _, k) in symbols.items()
               if k == 2 and any(n.endswith(f) or f in n for f in FAILURE_SYMBOLS)}
    costing = Costing()
    state = {"cycles": 0, "insns": 0, "pending": None, "failed": None}
    writes = []
    sheap = symbols.get("__sheap", (0, 0, 0))[0]
    # The lowest RAM address written above the statics (the stack's deepest point) and the
    # lowest SP seen at a block's start.
    low = {"write": None, "sp": None}

    def on_block(uc, addr, size, _user):
        if state["pending"] is not None:
            if addr != state["pending"]:
                state["cycles"] += P
            state["pending"] = None
        if addr in failure and state["failed"] is None:
            state["failed"] = addr
            uc.emu_stop()
        b = costing.block(bytes(uc.mem_read(addr, size)), addr)
        state["cycles"] += b.cycles
        state["insns"] += b.insns
        sp = uc.reg_read(U.UC_ARM_REG_SP)
        if low["sp"] is None or sp < low["sp"]:
            low["sp"] = sp
        if b.cond_fallthrough is not None:
            state["pending"] = b.cond_fallthrough
        if state["insns"] > BOOT_INSN_LIMIT:
            uc.emu_stop()

    def on_read(uc, _access, address, _size, _value, _user):
        try:
            _ready_bits(uc, address)
        except unicorn.UcError:
            pass

    def on_write(uc, _access, address, _size, value, _user):
        if 0x4000_0000 <= address < 0x6000_0000 or 0xE000_E000 <= address < 0xE010_0000:
            writes.append((state["cycles"], address, value & 0xFFFF_FFFF))
            if address == RCC_APB2RSTR and value & 1:
                # SYSCFG held in reset: its registers return to their reset values.
                uc.mem_write(SYSCFG_CFGR2, struct.pack("<I", 0))
        elif sheap <= address < RAM[0] + RAM[1]:
            if low["write"] is None or address < low["write"]:
                low["write"] = address

    uc.hook_add(unicorn.UC_HOOK_MEM_UNMAPPED, map_page)
    uc.hook_add(unicorn.UC_HOOK_BLOCK, on_block)
    uc.hook_add(unicorn.UC_HOOK_MEM_READ, on_read, begin=0x4000_0000, end=0x5FFF_FFFF)
    uc.hook_add(unicorn.UC_HOOK_MEM_WRITE, on_write)
    sp, reset = struct.unpack("<II", bytes(uc.mem_read(FLASH[0], 8)))
    uc.reg_write(U.UC_ARM_REG_SP, sp)
    try:
        uc.emu_start(reset | 1, 0, timeout=60_000_000)
    except unicorn.UcError as e:
        at = uc.reg_read(U.UC_ARM_REG_PC)
        # Unicorn does not implement WFE/WFI: the executor going to sleep ends the run.
        sleeps = (b"\x20\xbf", b"\x30\xbf")
        if bytes(uc.mem_read(at, 2)) not in sleeps and bytes(uc.mem_read(at - 2, 2)) not in sleeps:
            raise Failure(f"the boot trace stopped at {at:#010x}: {e}")
    pc = uc.reg_read(U.UC_ARM_REG_PC)
    where = next((n for lo, hi, n in reversed(by_start) if lo <= pc < hi), "unknown")
    reached = state["failed"] is None and EXECUTOR_IDLE in where
    final = {}
    for _, a, v in writes:
        final[a] = v
    for a in (RCC_BASE, RCC_CFGR):
        final[a] = struct.unpack("<I", bytes(uc.mem_read(a, 4)))[0]
    checks = [{"name": "boot reaches the executor without a fault", "pass": reached,
               "detail": f"stopped in {where}", "gate": True}]
    lowest = min(x for x in (low["write"], low["sp"]) if x is not None) \
        if low["write"] is not None or low["sp"] is not None else None
    checks += boot_checks(writes, symbols, final, enable_bsrr, enable_bit, lowest)
    guard_top = stack_guard_top(final)
    return {"cycles": state["cycles"], "instructions": state["insns"],
            "reached_executor": reached, "stopped_in": where, "checks": checks,
            "lowest_stack_address": lowest, "stack_guard_top": guard_top,
            "stack_margin_bytes": None if lowest is None else lowest - guard_top,
            "peripheral_writes": [[c, a, v] for c, a, v in writes]}


def boot_only(argv):
    """`--boot-only FIRMWARE_ELF BSRR BIT`: the firmware's failure paths and boot trace
    alone (a second image, whose control core the bench image already measured)."""
    try:
        safe = safe_state_paths(argv[2], int(argv[3], 0), int(argv[4], 0))
        boot = boot_trace(argv[2], int(argv[3], 0), int(argv[4], 0))
    except (Failure, OSError, ValueError) as e:
        print(f"target bench: {e}", file=sys.stderr)
        return 1
    result = {"panic_to_safe_cycles": safe["panic"]["cycles"], "safe_state": safe,
              "boot": boot, "boot_cycles": boot["cycles"],
              "boot_checks": [{"name": c["name"], "pass": c["pass"], "gate": c["gate"]}
                              for c in boot["checks"]]}
    json.dump(result, sys.stdout)
    sys.stdout.write("\n")
    return 0


def main(argv):
    usage = ("usage: driver.py FIRMWARE_BENCH_ELF "
             "[--safe-state FIRMWARE_ELF ENABLE_BSRR_ADDRESS ENABLE_BSRR_BIT]\n"
             "       driver.py --boot-only FIRMWARE_ELF ENABLE_BSRR_ADDRESS ENABLE_BSRR_BIT")
    if len(argv) == 5 and argv[1] == "--boot-only":
        return boot_only(argv)
    if len(argv) not in (2, 6) or (len(argv) == 6 and argv[2] != "--safe-state"):
        print(usage, file=sys.stderr)
        return 2
    start = time.time()
    errors = self_test()
    if errors:
        print("target bench: the timing table's self-test failed (did the capstone version "
              "change?):\n  " + "\n  ".join(errors), file=sys.stderr)
        return 1
    try:
        safe = None
        if len(argv) == 6:
            safe = safe_state_paths(argv[3], int(argv[4], 0), int(argv[5], 0))
        driver = Driver(argv[1])
        calls, overhead, image_stack = driver.session()
        result = summarise(calls, overhead, image_stack, driver.costing, time.time() - start)
        if safe is not None:
            result["safe_state"] = safe
            result["panic_to_safe_cycles"] = safe["panic"]["cycles"]
            boot = boot_trace(argv[3], int(argv[4], 0), int(argv[5], 0))
            result["boot"] = boot
            result["boot_cycles"] = boot["cycles"]
            result["boot_checks"] = [{"name": c["name"], "pass": c["pass"], "gate": c["gate"]}
                                     for c in boot["checks"]]
    except (Failure, OSError, ValueError) as e:
        print(f"target bench: {e}", file=sys.stderr)
        return 1
    json.dump(result, sys.stdout)
    sys.stdout.write("\n")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
