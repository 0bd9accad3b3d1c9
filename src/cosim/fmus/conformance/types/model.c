/*
 * types: one input and one output of every FMI 3.0 variable type. After step k (k = 1, 2, ...):
 *   y_<int type> = u_<int type> + k       (in the type's own arithmetic: unsigned values wrap)
 *   y_float32    = u_float32 * 0.5f + k
 *   mode         = (mode_in + k - 1) % 3 + 1    (Enumeration Mode: 1 idle, 2 run, 3 stop)
 *   odd          = k is odd                      (Boolean)
 *   label        = "<name> <k>"                  (String; name is a String input)
 *   data_out     = data_in with k added to every byte (Binary)
 * and `clock` is a Clock variable (FMI 3.0 clocks are not run by cosim: it is never connected).
 */
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

struct Model {
    double time;
    int8_t u_i8, y_i8; uint8_t u_u8, y_u8; int16_t u_i16, y_i16; uint16_t u_u16, y_u16;
    int32_t u_i32, y_i32; uint32_t u_u32, y_u32; int64_t u_i64, y_i64; uint64_t u_u64, y_u64;
    float u_f32, y_f32;
    int64_t mode_in, mode;
    bool odd;
    char name[64], label[64];
    struct { size_t size; uint8_t bytes[64]; } data_in, data_out;
    bool clock;
    int64_t k;
};

#include "../fmi3_runtime.c"

static void outputs(Instance *I) {
    struct Model *m = &I->m;
    m->y_i8 = (int8_t)(m->u_i8 + m->k); m->y_u8 = (uint8_t)(m->u_u8 + m->k);
    m->y_i16 = (int16_t)(m->u_i16 + m->k); m->y_u16 = (uint16_t)(m->u_u16 + m->k);
    m->y_i32 = (int32_t)(m->u_i32 + m->k); m->y_u32 = (uint32_t)(m->u_u32 + (uint32_t)m->k);
    m->y_i64 = m->u_i64 + m->k; m->y_u64 = m->u_u64 + (uint64_t)m->k;
    m->y_f32 = m->u_f32 * 0.5f + (float)m->k;
    m->mode = ((m->mode_in + m->k - 1) % 3 + 3) % 3 + 1;
    m->odd = m->k % 2 == 1;
    snprintf(m->label, sizeof m->label, "%s %lld", m->name, (long long)m->k);
    m->data_out.size = m->data_in.size;
    for (size_t i = 0; i < m->data_in.size; i++) m->data_out.bytes[i] = (uint8_t)(m->data_in.bytes[i] + m->k);
}

static bool model_variable(Instance *I, fmi3ValueReference vr, Var *v) {
    struct Model *m = &I->m;
    m->time = I->time;
    switch (vr) {
    case 0: *v = (Var){T_F64, &m->time, 1, K_READ_ONLY}; return true;
    case 1: *v = (Var){T_I8, &m->u_i8, 1, K_INPUT}; return true;
    case 2: *v = (Var){T_U8, &m->u_u8, 1, K_INPUT}; return true;
    case 3: *v = (Var){T_I16, &m->u_i16, 1, K_INPUT}; return true;
    case 4: *v = (Var){T_U16, &m->u_u16, 1, K_INPUT}; return true;
    case 5: *v = (Var){T_I32, &m->u_i32, 1, K_INPUT}; return true;
    case 6: *v = (Var){T_U32, &m->u_u32, 1, K_INPUT}; return true;
    case 7: *v = (Var){T_I64, &m->u_i64, 1, K_INPUT}; return true;
    case 8: *v = (Var){T_U64, &m->u_u64, 1, K_INPUT}; return true;
    case 11: *v = (Var){T_I8, &m->y_i8, 1, K_READ_ONLY}; return true;
    case 12: *v = (Var){T_U8, &m->y_u8, 1, K_READ_ONLY}; return true;
    case 13: *v = (Var){T_I16, &m->y_i16, 1, K_READ_ONLY}; return true;
    case 14: *v = (Var){T_U16, &m->y_u16, 1, K_READ_ONLY}; return true;
    case 15: *v = (Var){T_I32, &m->y_i32, 1, K_READ_ONLY}; return true;
    case 16: *v = (Var){T_U32, &m->y_u32, 1, K_READ_ONLY}; return true;
    case 17: *v = (Var){T_I64, &m->y_i64, 1, K_READ_ONLY}; return true;
    case 18: *v = (Var){T_U64, &m->y_u64, 1, K_READ_ONLY}; return true;
    case 20: *v = (Var){T_F32, &m->u_f32, 1, K_INPUT}; return true;
    case 21: *v = (Var){T_F32, &m->y_f32, 1, K_READ_ONLY}; return true;
    case 22: *v = (Var){T_I64, &m->mode_in, 1, K_INPUT}; return true;
    case 23: *v = (Var){T_I64, &m->mode, 1, K_READ_ONLY}; return true;
    case 24: *v = (Var){T_BOOL, &m->odd, 1, K_READ_ONLY}; return true;
    case 25: *v = (Var){T_STR, m->name, 1, K_INPUT}; return true;
    case 26: *v = (Var){T_STR, m->label, 1, K_READ_ONLY}; return true;
    case 27: *v = (Var){T_BIN, &m->data_in, 1, K_INPUT}; return true;
    case 28: *v = (Var){T_BIN, &m->data_out, 1, K_READ_ONLY}; return true;
    case 29: *v = (Var){T_CLOCK, &m->clock, 1, K_READ_ONLY}; return true;
    default: return false;
    }
}

static void model_start(Instance *I) {
    struct Model *m = &I->m;
    m->u_i8 = 125; m->u_u8 = 253; m->u_i16 = 32765; m->u_u16 = 65533;
    m->u_i32 = 2147483645; m->u_u32 = 4294967293u;
    m->u_i64 = INT64_C(9223372036854775805); m->u_u64 = UINT64_C(18446744073709551613);
    m->u_f32 = 0.1f; m->mode_in = 1;
    strcpy(m->name, "step");
    m->data_in.size = 3; m->data_in.bytes[0] = 0x0a; m->data_in.bytes[1] = 0x0b; m->data_in.bytes[2] = 0xfe;
    m->k = 0;
    outputs(I);
}

static fmi3Status model_exit_init(Instance *I) { outputs(I); return fmi3OK; }

static fmi3Status model_step(Instance *I, double t, double h, double *stop_at) {
    (void)t; (void)h; (void)stop_at;
    I->m.k++;
    outputs(I);
    return fmi3OK;
}
