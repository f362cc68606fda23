// Pieces the self-contained pages (report.html, viewer/index.html) share.
#pragma once

#include <string>
#include <vector>

namespace headforge {

// Text safe inside HTML elements and attribute values.
std::string HtmlEscape(const std::string& text);
// Standard base64 (RFC 4648), padded, for data: URLs.
std::string Base64(const std::vector<unsigned char>& bytes);
std::string Base64(const std::string& bytes);
// A script's text made safe to inline in <script>: no "</" can close the element.
std::string InlineScriptText(const std::string& text);

}  // namespace headforge
