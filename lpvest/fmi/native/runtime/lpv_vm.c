/*
 * lpvest native runtime: the stack machine that evaluates model formulas.
 *
 * The exporter (lpvest/fmi/native/_export.py) compiles a formula's validated
 * syntax tree into code words (lpv_core.h) with every name resolved to a variable
 * index and checked, and computes the deepest stack it needs (at most
 * LPV_VM_STACK). No text is ever read here. The power is the C library's pow, as
 * numpy's power of one float64 is; the functions are the C library's.
 */
#include <math.h>

#include "lpv_core.h"

static double apply(int fn, double x) {
    switch (fn) {
    case LPV_FN_SIN: return sin(x);
    case LPV_FN_COS: return cos(x);
    case LPV_FN_TAN: return tan(x);
    case LPV_FN_EXP: return exp(x);
    case LPV_FN_LOG: return log(x);
    case LPV_FN_SQRT: return sqrt(x);
    case LPV_FN_SINH: return sinh(x);
    case LPV_FN_COSH: return cosh(x);
    case LPV_FN_TANH: return tanh(x);
    case LPV_FN_ARCTAN: return atan(x);
    case LPV_FN_ABS: return fabs(x);
    default: return NAN;
    }
}

double lpv_formula_eval(const lpv_formula* f, const double* variables) {
    double stack[LPV_VM_STACK];
    int top = 0; /* number of values on the stack */
    const int32_t* pc = f->code;
    for (;;) {
        int32_t op = *pc++;
        switch (op) {
        case LPV_OP_END: return top == 1 ? stack[0] : NAN;
        case LPV_OP_CONST:
        case LPV_OP_VAR:
            if (top >= LPV_VM_STACK) return NAN;
            stack[top++] = op == LPV_OP_CONST ? f->constants[*pc] : variables[*pc];
            pc++;
            break;
        case LPV_OP_NEG:
            if (top < 1) return NAN;
            stack[top - 1] = -stack[top - 1];
            break;
        case LPV_OP_CALL:
            if (top < 1) return NAN;
            stack[top - 1] = apply(*pc++, stack[top - 1]);
            break;
        case LPV_OP_ADD:
        case LPV_OP_SUB:
        case LPV_OP_MUL:
        case LPV_OP_DIV:
        case LPV_OP_POW: {
            if (top < 2) return NAN;
            double b = stack[--top], a = stack[top - 1], r;
            if (op == LPV_OP_ADD) r = a + b;
            else if (op == LPV_OP_SUB) r = a - b;
            else if (op == LPV_OP_MUL) r = a * b;
            else if (op == LPV_OP_DIV) r = a / b;
            else r = pow(a, b);
            stack[top - 1] = r;
            break;
        }
        default: return NAN;
        }
    }
}
