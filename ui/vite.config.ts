import { defineConfig } from "vite";

// Reproducible output with fixed names (embedded by hal-sim/src/cli/ui.rs): no hashes, no
// source maps, one script and one style sheet.
export default defineConfig({
  base: "./",
  build: {
    outDir: "../hal-sim/ui-dist",
    emptyOutDir: true,
    sourcemap: false,
    modulePreload: false,
    cssCodeSplit: false,
    rollupOptions: {
      output: {
        entryFileNames: "assets/app.js",
        assetFileNames: "assets/app[extname]",
        inlineDynamicImports: true,
      },
    },
  },
});
