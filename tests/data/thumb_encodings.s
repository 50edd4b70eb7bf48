@ Encodings the firmware image does not contain, for the engine CPU's differential test
@ (tests/thumb_engine_test.py): each instruction, IT blocks as a group, run in the engine and
@ in unicorn from random states.
.syntax unified
.thumb
.text
.global _start
_start:
vcvtr.s32.f32 s0, s1
vcvtr.u32.f32 s2, s3
vcvt.s32.f32 s4, s4, #3
vcvt.u16.f32 s5, s5, #7
vcvt.f32.s16 s6, s6, #4
vcvt.f32.s32 s7, s7, #31
vfnma.f32 s8, s9, s10
vfnms.f32 s11, s12, s13
vnmla.f32 s14, s15, s16
vnmls.f32 s17, s18, s19
vnmul.f32 s20, s21, s22
vmla.f32 s23, s24, s25
vfms.f32 s26, s27, s28
vsqrt.f32 s29, s30
vcmpe.f32 s0, #0
vcmp.f32 s1, s2
vmov r0, r1, s2, s3
vmov s4, s5, r2, r3
vmov r4, r5, d3
vmov d4, r6, r7
vmov.f32 s8, #-2.5
vldmdb r0!, {s0-s3}
vstmdb r1!, {d2-d3}
vldmia r2, {d0-d1}
vstr d5, [r3, #-8]
vldr d6, [r4, #16]
vmsr fpscr, r5
vmrs r6, fpscr
smull r0, r1, r2, r3
smlal r4, r5, r6, r7
umlal r8, r9, r10, r11
sdiv r0, r1, r2
mls r3, r4, r5, r6
rbit r7, r8
rev16 r9, r10
revsh r11, r12
sxtb.w r0, r1, ror #8
sxtah r2, r3, r4, ror #16
uxtab r5, r6, r7
sxtb r1, r2
uxth r3, r4
sbfx r0, r1, #3, #17
bfc r2, #5, #9
bfi r3, r4, #0, #32
mov.w r5, r6, ror #7
mov.w r7, r8, rrx
asr.w r9, r10, r11
ror.w r12, r0, r1
rors r2, r3
adc.w r4, r5, r6, lsl #3
sbcs.w r7, r8, r9, asr #31
orn r10, r11, #0x00ff00ff
teq.w r12, r0, lsr #1
cmn.w r1, r2, lsl #30
rsb.w r3, r4, #0x3fc
adcs r5, r6
sbcs r7, r0
bics r1, r2
mvns r3, r4
muls r5, r6, r5
tst r0, r1
cmn r2, r3
negs r4, r5
ldrsh.w r0, [r1, r2, lsl #1]
ldrsb r3, [r4], #-7
strh r5, [r6, #-2]!
ldrd r0, r1, [r2], #-16
strd r3, r4, [r5, #8]!
ldmdb r6!, {r0-r3}
stmdb r7, {r1, r8, lr}
ldrh.w r8, [r9, #4095]
ldrb r10, [r11, #-255]
str.w r12, [r0, #-4]!
ldr r1, [r2, r3, lsl #3]
push.w {r4-r11, lr}
pop.w {r4-r11, lr}
movt r0, #0xbeef
addw r1, r2, #4095
subw r3, r4, #1234
add r5, sp, #1020
sub sp, sp, #508
add sp, #16
mrs r0, apsr
msr apsr_nzcvq, r1
mrs r2, control
mrs r3, basepri
msr basepri, r4
msr basepri_max, r5
mrs r6, faultmask
cpsie i
nop.w
dsb
dmb
isb
clz r7, r8
ittet eq
addeq r0, r1
subeq r2, r3
movne r4, #1
vaddeq.f32 s0, s1, s2
itete lt
lsllt r0, r1, #3
lsrge r2, r3, #5
asrlt r4, r5, #7
cmpge r6, r7
