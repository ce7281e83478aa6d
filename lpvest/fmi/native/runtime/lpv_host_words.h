/*
 * What both FMI backends check of a host's arguments, and say, the same way: the
 * native runtime (lpv_fmi2.c) and the status bridge of the Python FMUs
 * (lpvest/fmi/status_bridge.c, which includes this file by its relative path).
 * Self-contained: the C library's headers only.
 */
#ifndef LPV_HOST_WORDS_H
#define LPV_HOST_WORDS_H

#include <string.h>

/* why a status query is fmi2Discard (FMI 2.0, 4.2.3), after "<function>: " */
#define LPV_STATUS_NOT_AVAILABLE                                                                   \
    "this status is not available (only fmi2GetRealStatus(fmi2LastSuccessfulTime) and "          \
    "fmi2GetBooleanStatus(fmi2Terminated) are)"

/* 1 if text is well-formed UTF-8 (no overlong forms, no surrogates, at most U+10FFFF): FMI 2.0's
   strings. pythonfmu crashes the host or fails with fmi2Fatal on others, so both backends refuse
   them, in the same words. */
static int lpv_is_utf8(const char* text) {
    const unsigned char* p = (const unsigned char*)text;
    while (*p) {
        unsigned c = *p++;
        int more = c < 0x80 ? 0 : (c & 0xE0) == 0xC0 ? 1 : (c & 0xF0) == 0xE0 ? 2 : (c & 0xF8) == 0xF0 ? 3 : -1;
        if (more < 0) return 0;
        unsigned long cp = more == 0 ? c : more == 1 ? (c & 0x1F) : more == 2 ? (c & 0x0F) : (c & 0x07);
        for (int i = 0; i < more; i++, p++) {
            if ((*p & 0xC0) != 0x80) return 0;
            cp = (cp << 6) | (*p & 0x3F);
        }
        if ((more == 1 && cp < 0x80) || (more == 2 && cp < 0x800) || (more == 3 && cp < 0x10000) || cp > 0x10FFFF ||
            (cp >= 0xD800 && cp <= 0xDFFF))
            return 0;
    }
    return 1;
}

/* 1 if text has a character that is not white space: FMI 2.0 (2.1.5) asks for an instance name
   with at least one (the C locale's white space, whatever the host's locale) */
static int lpv_has_text(const char* text) {
    for (; *text; text++)
        if (!strchr(" \t\n\v\f\r", *text)) return 1;
    return 0;
}

/* a NULL argument of an FMU-state call (fmi2GetFMUstate ... fmi2DeSerializeFMUstate), after
   "<function>: " */
#define LPV_NULL_ARGUMENT "a NULL argument (a state, pointer or buffer)"

/* fmi2SerializeFMUstate's buffer smaller than the state: printf's format of the buffer's size and
   the state's, both unsigned long long */
#define LPV_BUFFER_TOO_SMALL "the buffer holds %llu bytes, the state needs %llu (fmi2SerializedFMUstateSize)"

/* fmi2DeSerializeFMUstate of bytes that do not start as a state of this backend does, after
   "fmi2DeSerializeFMUstate: " (what fmi2SetFMUstate checks of the rest, it says then) */
#define LPV_NOT_A_STATE "ArgumentError: not a serialized lpvest FMU state"

/* fmi2Instantiate with another FMU's GUID: printf's format of the host's GUID and this FMU's,
   each cut at 100 bytes (a message stays within 1000 characters) */
#define LPV_GUID_MISMATCH "fmi2Instantiate: GUID %.100s does not match this FMU's %.100s"

/* fmi2Instantiate with no resource location, after "fmi2Instantiate: " */
#define LPV_NO_RESOURCES "no resource location (NULL; FMI 2.0, 2.1.5: the URI of the FMU's resources folder)"

/* why an instance name is refused, after "fmi2Instantiate: " */
#define LPV_BLANK_NAME "the instance name is empty or white space only (FMI 2.0, 2.1.5: a non-empty name)"

#endif
